//! A real terminal for end-to-end tests: tmux runs the binary, send-keys
//! types, capture-pane reads the screen. Needs tmux (installed by .ci/setup).

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// A private tmux server running one session.
pub struct Tmux {
    socket: String,
}

impl Tmux {
    /// A server named after `tag` and this process; fails the test without tmux.
    pub fn new(tag: &str) -> Tmux {
        let t = Tmux {
            socket: format!("visage-test-{tag}-{}", std::process::id()),
        };
        let ok = Command::new("tmux")
            .arg("-V")
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false);
        assert!(
            ok,
            "tmux is needed for this test: apt-get install tmux (bash .ci/setup does)"
        );
        t
    }

    /// Runs a tmux command on this server; returns its standard output.
    pub fn cmd(&self, args: &[&str]) -> String {
        let out = Command::new("tmux")
            .arg("-L")
            .arg(&self.socket)
            .args(args)
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// Starts `command` in a detached 110×36 session.
    pub fn start(&self, command: &str) {
        self.start_sized(command, 110, 36);
    }

    /// Starts `command` in a detached session of `columns` × `rows`.
    pub fn start_sized(&self, command: &str, columns: u16, rows: u16) {
        let (c, r) = (columns.to_string(), rows.to_string());
        self.cmd(&["new-session", "-d", "-x", &c, "-y", &r, command]);
    }

    /// Resizes the session's window.
    pub fn resize(&self, columns: u16, rows: u16) {
        let (c, r) = (columns.to_string(), rows.to_string());
        self.cmd(&["resize-window", "-x", &c, "-y", &r]);
    }

    /// Types text character by character (spaces as `Space`).
    pub fn type_text(&self, text: &str) {
        let keys: Vec<String> = text
            .chars()
            .map(|c| match c {
                ' ' => "Space".to_string(),
                ';' => "\\;".to_string(),
                c => c.to_string(),
            })
            .collect();
        self.keys(&keys.iter().map(String::as_str).collect::<Vec<_>>());
    }

    /// The process id of the program the pane's shell runs.
    pub fn program_pid(&self) -> Option<String> {
        let shell = self.cmd(&["display-message", "-p", "#{pane_pid}"]);
        let out = Command::new("pgrep")
            .args(["-P", shell.trim()])
            .output()
            .ok()?;
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .next()
            .map(|l| l.trim().to_string())
    }

    /// The visible screen as text.
    pub fn screen(&self) -> String {
        self.cmd(&["capture-pane", "-p"])
    }

    /// Types keys (tmux key names), one at a time.
    pub fn keys(&self, keys: &[&str]) {
        for k in keys {
            self.cmd(&["send-keys", k]);
            std::thread::sleep(Duration::from_millis(60));
        }
    }

    /// Waits until the screen satisfies `pred`; panics with the screen after `limit`.
    pub fn wait_for(&self, what: &str, limit: Duration, pred: impl Fn(&str) -> bool) -> String {
        let start = Instant::now();
        loop {
            let s = self.screen();
            if pred(&s) {
                return s;
            }
            assert!(
                start.elapsed() < limit,
                "timed out waiting for {what}; screen:\n{s}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = Command::new("tmux")
            .arg("-L")
            .arg(&self.socket)
            .arg("kill-server")
            .output();
    }
}

/// Waits until the file exists and is not empty; returns its text.
pub fn wait_file(path: &Path, limit: Duration) -> String {
    let start = Instant::now();
    loop {
        if let Ok(s) = std::fs::read_to_string(path) {
            if !s.is_empty() {
                return s;
            }
        }
        assert!(start.elapsed() < limit, "{} never appeared", path.display());
        std::thread::sleep(Duration::from_millis(100));
    }
}
