//! `l3p-deploy` — `l3p deploy` as a binary of its own for the robot computer: the same flags and
//! behaviour, without the simulator, the learner, the registry store or the viewer (see the
//! `l3p_deploy_bin` library and ARCHITECTURE.md).

use std::process::ExitCode;

use clap::Parser;
use l3p_deploy_bin::{Cli, process};

fn main() -> ExitCode {
    process::init_logging();
    let cli = Cli::parse();
    // Robots added with `l3p robots add` ($L3P_ROBOTS_DIR, else ./l3p-data/robots), as `l3p` does.
    l3p_robot::added::load_added_robots(None);
    let verbose = cli.verbose || process::lib_backtrace_asked();
    if cli.verbose {
        // SAFETY: nothing has started another thread yet (logging set-up starts none), so no
        // concurrent reader of the environment exists; anyhow reads it when it captures a backtrace.
        #[allow(unsafe_code)]
        unsafe {
            std::env::set_var("RUST_LIB_BACKTRACE", "1");
        }
    }
    let result = cli
        .net
        .load()
        .and_then(|(safety, zenoh)| l3p_deploy_bin::run(&cli.deploy, zenoh, safety));
    process::exit_code(result, verbose)
}
