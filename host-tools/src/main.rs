//! `motorid`: identify a friction-aware motor model from logs, show where it fails, name the
//! missing physical effect, and take the coefficients to the board.
use clap::{Parser, Subcommand};
use motorid::cmd;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "motorid",
    version,
    about = "Identify, diagnose and deploy friction models of BLDC motors",
    long_about = "Identify, diagnose and deploy friction models of BLDC motors.\n\n\
        Typical loop: `simulate` (or record) a log, `fit` a model, `compare` it with the data, \
        `diagnose` what physical effect is missing, `fit --add` it, then `export` the \
        coefficients and `flash` or `upload` them to the board. `demo` runs the whole loop \
        on the built-in emulator.\n\n\
        Outputs are written whole or not at all and never over an input; their missing \
        folders are created (and announced) below the current directory, elsewhere only the \
        output's own folder, never at the root."
)]
struct Cli {
    /// Print what the command does on stderr: -v for the steps of the fits and the
    /// diagnosis, -vv for every iteration.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

/// Diagnostic output on stderr through `tracing`, at the level `-v` asks for; none by
/// default, so stderr carries only warnings and the `error:` line.
fn init_tracing(verbose: u8) {
    let level = match verbose {
        0 => return,
        1 => tracing::Level::DEBUG,
        _ => tracing::Level::TRACE,
    };
    tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .without_time()
        .with_target(false)
        .init();
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Simulate the emulated motor under one of the paper's excitations and write a log.
    Simulate(cmd::simulate::Args),
    /// Fit a linear, LuGre or SINDYc model to one or more logs.
    Fit(cmd::fit::Args),
    /// Run a model in free run on a log and score it (fit percentage).
    Compare(cmd::compare::Args),
    /// Find the physical effects the model is missing.
    Diagnose(cmd::diagnose::Args),
    /// The whole loop on the emulator: simulate, fit, diagnose, add, refit.
    Demo(cmd::demo::Args),
    /// Write the coefficient blob the firmware loads.
    Export(cmd::export::Args),
    /// Validate and decode a coefficient blob.
    Inspect(cmd::inspect::Args),
    /// Write a coefficient blob into the board's flash with a debug probe.
    Flash(cmd::flash::Args),
    /// Send a coefficient blob to the board over its serial port.
    Upload(cmd::upload::Args),
    /// Run an experiment on the board and save the log.
    Record(cmd::record::Args),
    /// Run the emulated board (control step + motor) behind a pseudo-terminal.
    Board(cmd::board::Args),
    /// Run the board's Hall commissioning and store the result.
    Commission(cmd::commission::Args),
    /// Clear the board's latched fault.
    ClearFault(cmd::clear_fault::Args),
    /// Closed-loop speed control with friction compensation on the emulated motor.
    Emulate(cmd::emulate::Args),
}

/// A command-line error as one `error:` line (clap's own text, its usage and tips left out);
/// `--help` and `--version` print as usual and exit 0.
fn clap_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp
        | ErrorKind::DisplayVersion
        | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => e.exit(),
        _ => {}
    }
    // The values clap quotes are the user's: echoed by the rule of every other message.
    let mut msg = one_line(&e.render().to_string());
    for (_, value) in e.context() {
        if let clap::error::ContextValue::String(s) = value {
            if s.chars().count() > motorid::log::ECHO_MAX {
                // clap's text has the value's escape sequences stripped: find it as shown.
                let shown = clap::builder::StyledStr::from(s.clone()).to_string();
                msg = msg.replace(shown.as_str(), &motorid::log::echo(s));
            }
        }
    }
    eprintln!("{}", motorid::log::escape_controls(&msg));
    ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2))
}

/// clap's message up to its first blank line (the usage and tips follow it), on one line.
fn one_line(text: &str) -> String {
    let mut parts = Vec::new();
    for line in text.lines() {
        let line = line.trim();
        if line.is_empty() {
            if !parts.is_empty() {
                break;
            }
            continue;
        }
        if line.starts_with("Usage:") || line.starts_with("For more information") {
            break;
        }
        parts.push(line);
    }
    let msg = parts.join(" ");
    let msg = msg.strip_prefix("error:").unwrap_or(&msg).trim();
    format!("error: {msg}")
}

fn main() -> ExitCode {
    // A panic is a bug, but the user still gets one `error:` line, not a backtrace.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!("error: internal error{at}: {msg} (please report this)");
    }));
    motorid::atomic::install_interrupt_cleanup();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return clap_error(e),
    };
    init_tracing(cli.verbose);
    let result = match cli.command {
        Command::Simulate(a) => cmd::simulate::run(a),
        Command::Fit(a) => cmd::fit::run(a),
        Command::Compare(a) => cmd::compare::run(a),
        Command::Diagnose(a) => cmd::diagnose::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Inspect(a) => cmd::inspect::run(a),
        Command::Flash(a) => cmd::flash::run(a),
        Command::Upload(a) => cmd::upload::run(a),
        Command::Record(a) => cmd::record::run(a),
        Command::Board(a) => cmd::board::run(a),
        Command::Commission(a) => cmd::commission::run(a),
        Command::ClearFault(a) => cmd::clear_fault::run(a),
        Command::Emulate(a) => cmd::emulate::run(a),
    };
    match result {
        Ok(()) => {
            motorid::warnings::flush();
            ExitCode::SUCCESS
        }
        Err(e) => {
            motorid::warnings::discard();
            // One line, and no control character from a path or a name reaches the terminal.
            let msg = motorid::log::escape_controls(&format!("{e:#}").replace('\n', " "));
            eprintln!("error: {msg}");
            ExitCode::FAILURE
        }
    }
}
