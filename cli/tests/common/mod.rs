//! Process helpers shared by the process-level tests.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Child, Command, Stdio};

/// The `[env]` and `[model]` sections of a small, fast training run for process-level tests: flat
/// ground, 2 s episodes, 32-unit layers, a 10-step diffusion.
pub const TINY_FLAT_TASK: &str = r#"
[env]
height_scan = false
episode_length_s = 2.0
[env.terrain]
preset = "flat"
[model]
encoder_hidden = [32]
core_hidden = [32]
decoder_hidden = [32]
critic_hidden = [32]
[model.recovery]
obs_hidden = [32]
diffusion_steps = 10
eval_samples = 32
"#;

/// Kills its processes when dropped, so a failing test leaves nothing behind.
pub struct Procs(pub Vec<(String, Child)>);

impl Procs {
    /// `l3p <args>` with stdout and stderr in `<log_dir>/<name>.log`.
    pub fn spawn(&mut self, name: &str, args: &[&str], log_dir: &Path) {
        let log = std::fs::File::create(log_dir.join(format!("{name}.log"))).unwrap();
        self.start(name, args, log.try_clone().unwrap(), log);
    }

    /// `l3p <args>` with stdout in `<log_dir>/<name>.out` and stderr in `<name>.log`.
    pub fn spawn_split(&mut self, name: &str, args: &[&str], log_dir: &Path) {
        let out = std::fs::File::create(log_dir.join(format!("{name}.out"))).unwrap();
        let log = std::fs::File::create(log_dir.join(format!("{name}.log"))).unwrap();
        self.start(name, args, out, log);
    }

    /// [`Procs::spawn_split`] with `log_dir` as the working directory (so `./l3p-data/robots`
    /// names the robots added there).
    pub fn spawn_split_in_dir(&mut self, name: &str, args: &[&str], log_dir: &Path) {
        let out = std::fs::File::create(log_dir.join(format!("{name}.out"))).unwrap();
        let log = std::fs::File::create(log_dir.join(format!("{name}.log"))).unwrap();
        let mut command = Command::new(env!("CARGO_BIN_EXE_l3p"));
        command.current_dir(log_dir);
        self.start_command(name, command, args, out, log);
    }

    fn start(&mut self, name: &str, args: &[&str], out: std::fs::File, log: std::fs::File) {
        let command = Command::new(env!("CARGO_BIN_EXE_l3p"));
        self.start_command(name, command, args, out, log);
    }

    fn start_command(
        &mut self,
        name: &str,
        mut command: Command,
        args: &[&str],
        out: std::fs::File,
        log: std::fs::File,
    ) {
        let child = command
            .args(args)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(log)
            .spawn()
            .unwrap();
        self.0.push((name.to_string(), child));
    }

    /// Waits up to `timeout` for `name` to exit on its own; `None` if it is still running.
    pub fn wait_exit(
        &mut self,
        name: &str,
        timeout: std::time::Duration,
    ) -> Option<std::process::ExitStatus> {
        let deadline = std::time::Instant::now() + timeout;
        let pos = self.0.iter().position(|(n, _)| n == name)?;
        loop {
            if let Ok(Some(status)) = self.0[pos].1.try_wait() {
                self.0.remove(pos);
                return Some(status);
            }
            if std::time::Instant::now() > deadline {
                return None;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }

    pub fn kill(&mut self, name: &str) {
        if let Some(pos) = self.0.iter().position(|(n, _)| n == name) {
            let (_, mut child) = self.0.remove(pos);
            child.kill().unwrap();
            child.wait().unwrap();
        }
    }
}

impl Drop for Procs {
    fn drop(&mut self) {
        for (_, child) in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Waits until something accepts TCP connections on 127.0.0.1:`port` (a spawned daemon has bound
/// the port it was given), or panics after `timeout`. Spawning the next process only then keeps it
/// from being handed the same, just-released ephemeral port for its own listener.
pub fn wait_for_port(port: u16, timeout: std::time::Duration, what: &str, log_dir: &Path) {
    let deadline = std::time::Instant::now() + timeout;
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if std::time::Instant::now() > deadline {
            panic!("{what} never listened on port {port}{}", log_tails(log_dir));
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// A free loopback port other than `taken`, and its endpoint, for the controller to listen on.
pub fn deploy_endpoint(taken: u16) -> (u16, String) {
    loop {
        let port = l3p_net::free_loopback_port().unwrap();
        if port != taken {
            return (port, format!("tcp/127.0.0.1:{port}"));
        }
    }
}

/// The last lines of every process log, for failure messages.
pub fn log_tails(dir: &Path) -> String {
    let mut out = String::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.extension().is_some_and(|e| e == "log") {
            let text = std::fs::read_to_string(&path).unwrap_or_default();
            // Backtrace frames hide the error message above them.
            let lines: Vec<&str> = text
                .lines()
                .filter(|l| {
                    let t = l.trim_start();
                    !(t.starts_with("at /")
                        || t.split_once(": ")
                            .is_some_and(|(n, _)| n.parse::<u32>().is_ok()))
                })
                .collect();
            out.push_str(&format!(
                "\n--- {} ---\n{}",
                path.display(),
                lines[lines.len().saturating_sub(15)..].join("\n")
            ));
        }
    }
    out
}
