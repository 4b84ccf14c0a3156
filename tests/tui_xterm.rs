//! The editor in a real sixel terminal: xterm emulating a VT340 under Xvfb runs
//! the binary; `xwd` takes a screenshot of the window; the viewport found in the
//! screenshot must match the frame visage renders for the same view; when the
//! terminal is killed the editor must exit (not spin on a dead tty). Needs Xvfb,
//! xterm, xwd and X fonts (installed by .ci/setup).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use visage::render::image::{psnr, RgbImage};

const TITLE: &str = "visage-xterm-e2e";
/// The database the editor opens (small, so a debug build starts quickly).
const DB: [&str; 4] = ["--gaussians-per-avatar", "4000", "--source-count", "3"];

/// Kills the X server and the terminal when the test ends, pass or fail.
struct Processes(Vec<Child>);

impl Drop for Processes {
    fn drop(&mut self) {
        for c in self.0.iter_mut().rev() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn require(tool: &str, package: &str) {
    let found = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
        .unwrap_or(false);
    assert!(
        found,
        "{tool} is needed for this test: apt-get install {package} (bash .ci/setup does)"
    );
}

/// Starts Xvfb on a free display and returns the display name.
fn start_xvfb(procs: &mut Processes) -> String {
    let base = 90 + std::process::id() % 400;
    for n in base..base + 50 {
        if Path::new(&format!("/tmp/.X{n}-lock")).exists() {
            continue;
        }
        let child = Command::new("Xvfb")
            .args([
                &format!(":{n}"),
                "-screen",
                "0",
                "1000x700x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start Xvfb");
        procs.0.push(child);
        let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(20) {
            if socket.exists() {
                return format!(":{n}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        panic!("Xvfb :{n} did not start");
    }
    panic!("no free X display");
}

/// An XWD (X window dump, ZPixmap, 24/32 bits per pixel) as RGB.
fn parse_xwd(bytes: &[u8]) -> RgbImage {
    let word = |i: usize| u32::from_be_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let header_size = word(0) as usize;
    let (width, height) = (word(4), word(5));
    let little_endian = word(7) == 0;
    let bits_per_pixel = word(11);
    let bytes_per_line = word(12) as usize;
    let masks = [word(14), word(15), word(16)];
    let colours = word(19) as usize;
    assert_eq!(word(2), 2, "xwd: not a ZPixmap");
    assert_eq!(bits_per_pixel, 32, "xwd: expected 32 bits per pixel");
    let data = &bytes[header_size + 12 * colours..];
    let mut image = RgbImage::new(width, height, [0; 3]);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let at = y * bytes_per_line + 4 * x;
            let raw: [u8; 4] = data[at..at + 4].try_into().unwrap();
            let v = if little_endian {
                u32::from_le_bytes(raw)
            } else {
                u32::from_be_bytes(raw)
            };
            let o = 3 * (y * width as usize + x);
            for (c, m) in masks.iter().enumerate() {
                image.pixels[o + c] = ((v & m) >> m.trailing_zeros()) as u8;
            }
        }
    }
    image
}

fn screenshot(display: &str) -> Option<RgbImage> {
    let out = Command::new("xwd")
        .args(["-display", display, "-name", TITLE, "-silent"])
        .output()
        .ok()?;
    (out.status.success() && out.stdout.len() > 100).then(|| parse_xwd(&out.stdout))
}

/// The viewport: the sixel image has a black background that reaches its left
/// and right edges, so its edge columns are long vertical black runs, many
/// side by side with the same extent (box-drawing borders are single columns,
/// text glyphs short). Returns (x, y, width, height).
fn find_viewport(shot: &RgbImage) -> Option<(u32, u32, u32, u32)> {
    let black = |x: u32, y: u32| shot.pixel(x, y).iter().all(|&c| c < 8);
    let column_run = |x: u32| {
        let (mut best, mut run) = ((0, 0), 0);
        for y in 0..=shot.height {
            if y < shot.height && black(x, y) {
                run += 1;
            } else {
                if run > best.1 {
                    best = (y - run, run);
                }
                run = 0;
            }
        }
        best
    };
    let margin = 4; // the window border is black too
    let runs: Vec<(u32, u32)> = (0..shot.width).map(column_run).collect();
    let left = (margin..shot.width.saturating_sub(margin + 16)).find(|&x| {
        runs[x as usize].1 >= 64 && (1..16).all(|k| runs[(x + k) as usize] == runs[x as usize])
    })?;
    let (top, height) = runs[left as usize];
    let right = (left..shot.width - margin)
        .filter(|&x| runs[x as usize] == (top, height))
        .max()?;
    Some((left, top, right + 1 - left, height))
}

/// Coloured pixels above the viewport (the source strip): thumbnails of
/// faces have them, text and borders in default colours do not.
fn thumbnail_pixels(shot: &RgbImage, (x, y, w, _): (u32, u32, u32, u32)) -> usize {
    let strip = crop(shot, (x, 0, w, y.saturating_sub(20)));
    strip
        .pixels
        .chunks(3)
        .filter(|p| {
            let (hi, lo) = (*p.iter().max().unwrap(), *p.iter().min().unwrap());
            hi > 90 && hi - lo > 40
        })
        .count()
}

fn crop(image: &RgbImage, (x0, y0, w, h): (u32, u32, u32, u32)) -> RgbImage {
    let mut out = RgbImage::new(w, h, [0; 3]);
    for y in 0..h {
        for x in 0..w {
            let o = 3 * (y * w + x) as usize;
            out.pixels[o..o + 3].copy_from_slice(&image.pixel(x0 + x, y0 + y));
        }
    }
    out
}

/// Whether a process whose command line contains `marker` is alive.
fn editor_running(marker: &str) -> bool {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return false;
    };
    entries.flatten().any(|e| {
        let alive = std::fs::read_to_string(e.path().join("stat"))
            .map(|s| !s.contains(") Z "))
            .unwrap_or(false);
        alive
            && std::fs::read(e.path().join("cmdline"))
                .map(|c| String::from_utf8_lossy(&c).contains(marker))
                .unwrap_or(false)
    })
}

/// An xterm (VT340, 256 colour registers, 110×36) on `display` that runs
/// visage with the arguments the caller adds.
fn xterm_running_visage(display: &str) -> Command {
    let mut xterm = Command::new("xterm");
    xterm
        .env("VISAGE_CACHE_DIR", common::test_cache_dir())
        .args(["-display", display, "-T", TITLE, "-ti", "vt340"])
        .args(["-geometry", "110x36+0+0"])
        .args(["-xrm", "XTerm*numColorRegisters: 256"])
        .arg("-e")
        .arg(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    xterm
}

/// Kills the terminal (the last process started) and waits for the program
/// it ran, found by `marker`, to end: a hung-up tty must not leave it running.
fn kill_terminal_and_wait(procs: &mut Processes, marker: &str) {
    let mut xterm = procs.0.pop().unwrap();
    xterm.kill().unwrap();
    xterm.wait().unwrap();
    let killed = Instant::now();
    while editor_running(marker) {
        assert!(
            killed.elapsed() < Duration::from_secs(10),
            "{marker}: still running after its terminal was killed"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn rendered(size: (u32, u32), dir: &Path) -> RgbImage {
    let path = dir.join(format!("expected-{}x{}.png", size.0, size.1));
    let out = Command::new(env!("CARGO_BIN_EXE_visage"))
        .arg("render")
        .args(DB)
        .args(["--size", &format!("{}x{}", size.0, size.1)])
        .args(["--renderer", "cpu", "-o"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    RgbImage::load_png(&path).unwrap()
}

#[test]
fn xterm_vt340_shows_the_rendered_view_as_sixel() {
    for (tool, package) in [("Xvfb", "xvfb"), ("xterm", "xterm"), ("xwd", "x11-apps")] {
        require(tool, package);
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xterm-e2e");
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("config");
    std::fs::create_dir_all(&config).unwrap();
    // The journal's path marks the editor's process (its command line holds it).
    let journal = dir.join(format!("journal-{}.vsg", std::process::id()));
    let _ = std::fs::remove_file(&journal);
    let mut procs = Processes(Vec::new());
    let display = start_xvfb(&mut procs);
    let xterm = xterm_running_visage(&display)
        .args(["--graphics", "sixel", "--renderer", "cpu", "--record"])
        .arg(&journal)
        .args(DB)
        .env("XDG_CONFIG_HOME", &config)
        .spawn()
        .expect("start xterm");
    procs.0.push(xterm);

    let start = Instant::now();
    let mut expected: Option<RgbImage> = None;
    let mut last = String::from("no screenshot yet");
    while start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(500));
        let Some(shot) = screenshot(&display) else {
            continue;
        };
        shot.save_png(&dir.join("screenshot.png")).unwrap();
        let Some(viewport) = find_viewport(&shot) else {
            last = "no viewport in the screenshot".into();
            continue;
        };
        let (_, _, w, h) = viewport;
        if expected.as_ref().map(|e| (e.width, e.height)) != Some((w, h)) {
            expected = Some(rendered((w, h), &dir));
        }
        let shown = crop(&shot, viewport);
        let db = psnr(&shown, expected.as_ref().unwrap()).expect("same size");
        let faces = thumbnail_pixels(&shot, viewport);
        last = format!(
            "viewport {viewport:?} at {db:.1} dB, {faces} coloured pixels in the source strip"
        );
        // Sixel through 256 colour registers without dithering: ~40 dB here;
        // the source strip shows each source's face (skin, hair, lips: colour
        // that the strip's text and borders never have).
        if db >= 30.0 && faces > 300 {
            eprintln!("xterm showed the view: {last}");
            shown.save_png(&dir.join("viewport.png")).unwrap();
            let marker = journal.display().to_string();
            assert!(
                editor_running(&marker),
                "the editor's process was not found"
            );
            // Kill the terminal: the tty hangs up and the editor must end.
            kill_terminal_and_wait(&mut procs, &marker);
            assert!(journal.is_file(), "the session journal was not written");
            return;
        }
    }
    panic!(
        "xterm never showed the view ({last}); screenshot in {}",
        dir.display()
    );
}

/// A participant's session in a sixel terminal: the avatar shows as a
/// picture in the viewport, and when the terminal is killed (a dropped
/// connection) the session ends with its journal on disk.
#[test]
fn xterm_vt340_runs_a_study_session_as_sixel() {
    for (tool, package) in [("Xvfb", "xvfb"), ("xterm", "xterm"), ("xwd", "x11-apps")] {
        require(tool, package);
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("xterm-study");
    let study = dir.join(format!("study-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&study);
    std::fs::create_dir_all(&dir).unwrap();
    let built = Command::new(env!("CARGO_BIN_EXE_visage"))
        .args(["study", "build", "studies/builtin/spec.toml", "--out"])
        .arg(&study)
        // The run's fit options: the avatars are shown from their stored fits.
        .args(["--seam-fit", "2", "--seam-fit-size", "16"])
        .output()
        .unwrap();
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stderr)
    );
    let mut procs = Processes(Vec::new());
    let display = start_xvfb(&mut procs);
    let xterm = xterm_running_visage(&display)
        .args(["study", "run"])
        .arg(&study)
        .args([
            "--participant",
            "xterm",
            "--graphics",
            "sixel",
            "--renderer",
            "cpu",
            // The edited avatars fit their seams before they show: a
            // small fit keeps that path in the run without its minutes.
            "--seam-fit",
            "2",
            "--seam-fit-size",
            "16",
        ])
        .spawn()
        .expect("start xterm");
    procs.0.push(xterm);

    let marker = study.display().to_string();
    let start = Instant::now();
    let mut last = String::from("no screenshot yet");
    while start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(500));
        let Some(shot) = screenshot(&display) else {
            continue;
        };
        let Some(viewport) = find_viewport(&shot) else {
            last = "no viewport in the screenshot".into();
            continue;
        };
        // The head fills the middle of the viewport: mostly lit, not black.
        let (x, y, w, h) = viewport;
        let middle = crop(&shot, (x + w * 2 / 5, y + h / 3, w / 5, h / 3));
        let lit = middle
            .pixels
            .chunks(3)
            .filter(|p| p.iter().map(|&c| c as u32).sum::<u32>() > 150)
            .count();
        let share = lit as f64 / (middle.width * middle.height) as f64;
        last = format!(
            "viewport {viewport:?}, {:.0}% of its middle lit",
            share * 100.0
        );
        if share > 0.8 {
            shot.save_png(&dir.join("screenshot.png")).unwrap();
            assert!(
                editor_running(&marker),
                "the session's process was not found"
            );
            kill_terminal_and_wait(&mut procs, &marker);
            let journal = std::fs::read_to_string(study.join("answers/xterm.jsonl")).unwrap();
            assert!(
                journal.starts_with("{\"participant\":\"xterm\""),
                "{journal}"
            );
            return;
        }
    }
    panic!(
        "xterm never showed the avatar ({last}); see {}",
        dir.display()
    );
}
