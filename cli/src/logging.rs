//! `tracing` set-up: logs go to stderr, filtered by `RUST_LOG` (default: l3p's `info`, Zenoh's
//! `warn` — its session INFO lines, such as the endpoints it can be reached at, are noise on every
//! call of a one-shot command).

use tracing_subscriber::EnvFilter;

/// Logging, plus quiet exit on a closed stdout: `l3p registry list | head` must not print a panic
/// (Rust ignores SIGPIPE, so `println!` panics with "Broken pipe" instead of the process dying).
pub fn init() {
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
