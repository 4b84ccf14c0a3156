//! Terminal plumbing shared by the editor, the study session and the terminal
//! benchmark: taking the terminal over and giving it back on every exit path
//! (quit, error, panic, SIGINT, SIGTERM, SIGHUP), one write per frame, a
//! thread that reads input, hang-up detection, and a yes/no question asked
//! before the terminal changes.

use std::io::{BufRead, Write};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{channel, Receiver};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crossterm::event::{self, Event};
use crossterm::{cursor, execute, terminal};

use super::graphics::{kitty_delete_all, SYNC_END};
use crate::error::{Error, Result};

/// A `Write` that collects ratatui's output so a frame goes out in one write.
#[derive(Clone, Default)]
pub struct Collector(Arc<Mutex<Vec<u8>>>);

impl Collector {
    /// Takes the bytes collected so far.
    pub fn take(&self) -> Vec<u8> {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl Write for Collector {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Restores the terminal when dropped (normal exit, error, unwinding panic).
pub struct TerminalGuard {
    kitty: bool,
}

/// Gives the terminal back: kitty images deleted, synchronized output ended,
/// mouse capture off, the main screen, the cursor and cooked mode back.
pub fn restore_terminal(kitty: bool) {
    let mut out = std::io::stdout();
    if kitty {
        let _ = out.write_all(&kitty_delete_all());
    }
    let _ = out.write_all(SYNC_END);
    let _ = execute!(
        out,
        event::DisableMouseCapture,
        terminal::LeaveAlternateScreen,
        cursor::Show
    );
    let _ = terminal::disable_raw_mode();
    let _ = out.flush();
}

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        restore_terminal(self.kitty);
    }
}

/// Which of SIGINT, SIGTERM or SIGHUP asked the program to stop: a long job
/// polls it, saves its work and exits with 128 + the signal.
#[derive(Clone, Debug)]
pub struct StopSignal(Arc<AtomicUsize>);

impl StopSignal {
    /// Installs the handlers (instead of the default of dying at once).
    pub fn install() -> Result<StopSignal> {
        let flag = Arc::new(AtomicUsize::new(0));
        for signal in [
            signal_hook::consts::SIGINT,
            signal_hook::consts::SIGTERM,
            signal_hook::consts::SIGHUP,
        ] {
            signal_hook::flag::register_usize(signal, Arc::clone(&flag), signal as usize)
                .map_err(|e| Error::terminal(format!("cannot install a signal handler: {e}")))?;
        }
        Ok(StopSignal(flag))
    }

    /// The signal received, if any.
    pub fn received(&self) -> Option<i32> {
        match self.0.load(Ordering::Relaxed) {
            0 => None,
            s => Some(s as i32),
        }
    }

    /// The error a job stopped by `signal` ends with (exit 128 + signal).
    pub fn stopped(signal: i32, message: impl Into<String>) -> Error {
        Error::Interrupted {
            signal,
            message: message.into(),
        }
    }
}

/// The name of a stop signal, for messages.
pub fn signal_name(signal: i32) -> &'static str {
    match signal {
        libc::SIGINT => "SIGINT",
        libc::SIGTERM => "SIGTERM",
        libc::SIGHUP => "SIGHUP",
        _ => "a signal",
    }
}

/// Takes over the terminal (raw mode, alternate screen, mouse, no cursor)
/// until the guard drops, restoring it on panics too; the returned flag
/// tells when SIGINT, SIGTERM or SIGHUP arrives.
pub fn enter_terminal(kitty: bool) -> Result<(TerminalGuard, StopSignal)> {
    let stop = StopSignal::install()?;
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        restore_terminal(kitty);
        default_hook(info);
    }));
    terminal::enable_raw_mode()
        .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
    let guard = TerminalGuard { kitty };
    execute!(
        std::io::stdout(),
        terminal::EnterAlternateScreen,
        event::EnableMouseCapture,
        cursor::Hide
    )
    .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
    Ok((guard, stop))
}

/// Writes a frame's bytes to the terminal in one write.
pub fn write_to_terminal(bytes: &[u8]) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    stdout
        .write_all(bytes)
        .and_then(|_| stdout.flush())
        .map_err(|e| Error::terminal(format!("cannot write to the terminal: {e}")))
}

/// Reads terminal events on their own thread. crossterm's `poll` can spin
/// without returning once the terminal hangs up; on this thread that costs
/// nothing, since the editor loop notices the hang-up and the process exits.
pub fn spawn_input_reader() -> Receiver<Event> {
    let (tx, rx) = channel();
    std::thread::spawn(move || loop {
        match event::poll(Duration::from_millis(50)) {
            Ok(true) => match event::read() {
                Ok(e) => {
                    if tx.send(e).is_err() {
                        return;
                    }
                }
                Err(_) => return,
            },
            Ok(false) => {}
            Err(_) => return,
        }
    });
    rx
}

/// True when standard input's terminal has hung up or is gone.
pub fn terminal_hung_up() -> bool {
    let mut fd = libc::pollfd {
        fd: libc::STDIN_FILENO,
        events: 0,
        revents: 0,
    };
    // SAFETY: one valid pollfd, zero timeout; poll only writes `revents`.
    let n = unsafe { libc::poll(&mut fd, 1, 0) };
    n > 0 && fd.revents & (libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0
}

/// Asks a yes/no question on standard error and reads the answer from
/// standard input (before the terminal is taken over). Anything but an
/// answer starting with y or n asks again; end of input means no.
pub fn ask_yes_no(question: &str) -> bool {
    let stdin = std::io::stdin();
    loop {
        eprint!("{question} [y/n] ");
        let _ = std::io::stderr().flush();
        let mut line = String::new();
        match stdin.lock().read_line(&mut line) {
            Ok(0) | Err(_) => return false,
            Ok(_) => {}
        }
        match line.trim().chars().next().map(|c| c.to_ascii_lowercase()) {
            Some('y') => return true,
            Some('n') => return false,
            _ => eprintln!("please answer y or n"),
        }
    }
}
