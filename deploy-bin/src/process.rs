//! Process glue shared by `l3p` and `l3p-deploy`: logging set-up, the tokio runtime, Ctrl-C/SIGTERM
//! → cancellation, and how a command's result becomes the error report and exit status.

use std::process::ExitCode;

use tokio_util::sync::CancellationToken;
use tracing_subscriber::EnvFilter;

/// Logging to stderr, filtered by `RUST_LOG` (default: l3p's `info`, Zenoh's `warn` — its session
/// INFO lines, such as the endpoints it can be reached at, are noise on every call of a one-shot
/// command), plus a quiet exit on a closed stdout: `l3p registry list | head` must not print a panic
/// (Rust ignores SIGPIPE, so `println!` panics with "Broken pipe" instead of the process dying).
pub fn init_logging() {
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.contains("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(141); // 128 + SIGPIPE, as a shell reports it
        }
        default_hook(info);
    }));
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        EnvFilter::new("info,zenoh=warn,zenoh_transport=warn,zenoh_link_tcp=warn")
    });
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
}

/// The command stopped because its user asked it to (Ctrl-C, SIGTERM) and left its work resumable:
/// an expected end, which `main` reports as its message and exit status 130 — never with the
/// backtrace that `RUST_BACKTRACE=1` adds to a failure.
#[derive(Debug)]
pub struct Interrupted(pub String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// Whether `RUST_LIB_BACKTRACE` asks for error backtraces (set and not `0`, as std reads it).
/// `RUST_BACKTRACE` alone does not: it is for panics, and CI sets it for every command.
pub fn lib_backtrace_asked() -> bool {
    std::env::var_os("RUST_LIB_BACKTRACE").is_some_and(|v| v != "0")
}

/// A failed command's error as `main` prints it: `error: ` and the chain of causes on one line
/// (`context: cause: …`, hint lines as the messages hold them); `verbose` (`-v`, or
/// `RUST_LIB_BACKTRACE`) adds anyhow's full report — the causes one per line and the stack
/// backtrace when one was captured.
pub fn error_report(error: &anyhow::Error, verbose: bool) -> String {
    if verbose {
        format!("error: {error:?}")
    } else {
        format!("error: {error:#}")
    }
}

/// A command's result as the process's exit status: success, 130 with the message for an
/// [`Interrupted`] command, else 1 after printing the [`error_report`].
pub fn exit_code(result: anyhow::Result<()>, verbose: bool) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => match e.downcast_ref::<Interrupted>() {
            Some(interrupted) => {
                eprintln!("{interrupted}");
                ExitCode::from(130)
            }
            None => {
                eprintln!("{}", error_report(&e, verbose));
                ExitCode::FAILURE
            }
        },
    }
}

/// A multi-threaded tokio runtime for Zenoh and the daemon loops (heavy work runs on blocking threads).
pub fn tokio_runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
}

/// A token cancelled by the first Ctrl-C (SIGINT) or SIGTERM; a second Ctrl-C exits at once.
pub fn cancel_on_signal() -> CancellationToken {
    let cancel = CancellationToken::new();
    let token = cancel.clone();
    tokio::spawn(async move {
        let term = async {
            #[cfg(unix)]
            if let Ok(mut s) =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            {
                s.recv().await;
                return;
            }
            std::future::pending::<()>().await
        };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term => {}
        }
        tracing::info!("stopping (signal received; a second Ctrl-C exits immediately)");
        token.cancel();
        let _ = tokio::signal::ctrl_c().await;
        std::process::exit(130);
    });
    cancel
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_prints_its_chain_and_hint_without_a_backtrace_unless_verbose() {
        let error = anyhow::anyhow!("leg joints without limits\nhint: add <limit/>")
            .context("adding lab_dog.urdf");
        let short = error_report(&error, false);
        assert_eq!(
            short,
            "error: adding lab_dog.urdf: leg joints without limits\nhint: add <limit/>"
        );
        let long = error_report(&error, true);
        assert!(
            long.starts_with("error: adding lab_dog.urdf") && long.contains("Caused by:"),
            "{long}"
        );
    }
}
