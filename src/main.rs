//! The `visage` binary: see `visage --help`.

fn main() -> std::process::ExitCode {
    visage::cli::run()
}
