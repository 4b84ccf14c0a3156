//! The `visage` binary: see `visage --help`.

fn main() -> std::process::ExitCode {
    // Mesa's device-select layer only reorders adapters (wgpu picks its own) and
    // prints an XDG_RUNTIME_DIR warning over SSH; switch it off unless the user chose.
    // Safe here: no other thread exists yet.
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
    // A closed pipe (`visage info | head`) ends the program quietly, as it
    // ends other command-line tools, instead of a panic in println!.
    // SAFETY: restoring the default disposition of one signal before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    visage::cli::run()
}
