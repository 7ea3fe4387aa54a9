//! `lsydrelight`, the project's command-line tool. One module per subcommand
//! (`relight`, `capture`, `train`), sharing the conventions in
//! [`exit`] (exit codes and error messages), [`interrupt`] (Ctrl-C),
//! [`partial`] (outputs renamed into place only when complete) and
//! [`progress`] (progress bars).

mod capture;
mod exit;
mod interrupt;
mod partial;
mod progress;
mod relight;
mod train;

use clap::{Parser, Subcommand};

/// Relights a face in video with a network personalised to that person.
#[derive(Parser)]
#[command(name = "lsydrelight", version, after_help = exit::codes_help!())]
struct Cli {
    /// Print nothing but errors: no progress bar, no summary
    #[arg(short, long, global = true)]
    quiet: bool,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Relight(relight::Args),
    Capture(capture::Args),
    Train(train::Args),
}

fn main() -> exit::Status {
    let cli = Cli::parse();
    if let Err(e) = gst::init() {
        eprintln!("error: cannot start GStreamer: {e}; is GStreamer 1.22 or newer installed?");
        return exit::Status::Failure;
    }
    if let Err(e) = gstlsydrelight::plugin_register_static() {
        eprintln!("error: cannot register the lsydrelight element: {e}");
        return exit::Status::Failure;
    }
    // The simulated webcam, so that a capture can film a simulated person.
    if let Err(e) = gstdeskstage::plugin_register_static() {
        eprintln!("error: cannot register the deskstagecam element: {e}");
        return exit::Status::Failure;
    }
    interrupt::install();
    match cli.command {
        Command::Relight(args) => relight::run(args, cli.quiet),
        Command::Capture(args) => capture::run(args, cli.quiet),
        Command::Train(args) => train::run(args, cli.quiet),
    }
}
