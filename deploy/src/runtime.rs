//! The deploy daemon ([`run_deploy`]): Zenoh I/O around the [`Controller`] in a 50 Hz deadline loop
//! on its own OS thread.
//!
//! - State in: a [`LatestSlot`] on `l3p/robot/<id>/state` (newest valid state only; rejects counted).
//! - Commands out: `l3p/robot/<id>/command`, express, `Priority::RealTime`, `CongestionControl::Drop`.
//! - Operator in: `l3p/robot/<id>/operator` (`l3p operate`), applied at the next tick.
//! - Status out: JSON [`DeployStatus`] on `l3p/robot/<id>/deploy/status` every second and on every
//!   mode change.
//!
//! Stopping (cancellation, `--duration`, operator `Stop`) sends damping for `stop_damping_s` first.

use std::time::{Duration, Instant};

use l3p_proto::{
    ControlMode, DeployStatus, OperatorAction, OperatorCommand, RobotState, WIRE_VERSION, codec,
    keys,
};
use l3p_robot::catalog::RobotSpec;
use tokio_util::sync::CancellationToken;
use tracing::{info, warn};
use zenoh::Wait;

use crate::DeployError;
use crate::artifact::LoadedPolicy;
use crate::controller::{Controller, ExportedPolicy, Latest, SafetyConfig};
use crate::latest::{LatestSlot, now_unix_ns};
use crate::pacer::Pacer;
use crate::stats::Percentiles;

/// What to deploy where.
#[derive(Debug, Clone)]
pub struct DeployOptions {
    pub robot: &'static RobotSpec,
    pub robot_id: String,
    pub safety: SafetyConfig,
    /// Stop (through damping) after this long; `None`: run until cancelled.
    pub duration: Option<Duration>,
    /// How often the status is published.
    pub status_every: Duration,
    /// Why the Zenoh links are not authenticated, when the operator accepted that (`l3p deploy
    /// --insecure`): logged as a warning and carried in every status.
    pub insecure: Option<String>,
    /// A zero yaw-rate command holds the heading (`--heading-hold`, [`crate::heading::HeadingHold`]).
    pub heading_hold: bool,
}

/// Timing samples kept for percentiles: 10 minutes at 50 Hz.
const STATS_WINDOW: usize = 30_000;

/// Runs `loaded` as the controller of robot `opts.robot_id` until cancelled, `opts.duration` passes
/// or an operator sends `Stop`. Returns the final status.
pub async fn run_deploy(
    session: &zenoh::Session,
    loaded: LoadedPolicy,
    opts: DeployOptions,
    cancel: CancellationToken,
) -> Result<DeployStatus, DeployError> {
    l3p_proto::keys::validate_segment("robot id", &opts.robot_id)
        .map_err(|e| DeployError::Config(e.to_string()))?;
    let controller = Controller::new(
        &opts.robot_id,
        loaded.io.clone(),
        loaded.action_scale,
        opts.safety.clone(),
    )?;
    let controller = if opts.heading_hold {
        controller.with_heading_hold()
    } else {
        controller
    };
    let zerr = |e: zenoh::Error| DeployError::Zenoh(e.to_string());

    let believable_io = loaded.io.clone();
    let states = LatestSlot::<RobotState>::subscribe(
        session,
        keys::robot_state(&opts.robot_id),
        &opts.robot_id,
        opts.robot.joint_names.len(),
        Some(Box::new(move |s: &RobotState| {
            crate::observation::plausible_state(s, &believable_io)
        })),
    )
    .await?;
    let (op_tx, op_rx) = std::sync::mpsc::channel::<OperatorAction>();
    let op_sub = {
        let robot_id = opts.robot_id.clone();
        session
            .declare_subscriber(keys::robot_operator(&opts.robot_id))
            .callback(move |sample| {
                match codec::decode::<OperatorCommand>(&sample.payload().to_bytes()) {
                    Ok(c) if c.robot_id == robot_id => {
                        let _ = op_tx.send(c.action);
                    }
                    Ok(c) => warn!("operator command for robot id {:?} ignored", c.robot_id),
                    Err(e) => warn!("malformed operator command: {e}"),
                }
            })
            .await
            .map_err(zerr)?
    };
    let commands = l3p_net::declare_control_publisher(session, keys::robot_command(&opts.robot_id))
        .await
        .map_err(zerr)?;
    let status_pub = session
        .declare_publisher(keys::robot_deploy_status(&opts.robot_id))
        .await
        .map_err(zerr)?;

    info!(
        robot = opts.robot.name,
        robot_id = %opts.robot_id,
        policy = %loaded.reference,
        sha256 = %loaded.sha256,
        hz = 1.0 / loaded.io.control_dt,
        "deploy armed: zero-torque until the first state, then ramp to the default pose, then policy"
    );
    let loop_state = LoopState {
        controller,
        policy: ExportedPolicy::new(loaded.policy.clone()),
        status: DeployStatus {
            wire_version: WIRE_VERSION,
            robot_id: opts.robot_id.clone(),
            robot: opts.robot.name.into(),
            policy: loaded.reference.clone(),
            mode: ControlMode::ZeroTorque,
            fault: None,
            ticks: 0,
            commands: 0,
            overruns: 0,
            rejected_states: 0,
            period_error_p50_us: 0.0,
            period_error_p99_us: 0.0,
            inference_p50_us: 0.0,
            inference_p99_us: 0.0,
            warning: opts.insecure.clone(),
        },
    };
    let period = Duration::from_secs_f32(loaded.io.control_dt);
    let result = tokio::task::spawn_blocking(move || {
        control_loop(
            loop_state,
            period,
            &opts,
            &states,
            &op_rx,
            &cancel,
            |bytes| commands.put(bytes).wait().map_err(zerr),
            |bytes| status_pub.put(bytes).wait().map_err(zerr),
        )
    })
    .await
    .map_err(|e| DeployError::Config(format!("control loop thread: {e}")))?;
    drop(op_sub);
    result
}

struct LoopState {
    controller: Controller,
    policy: ExportedPolicy,
    status: DeployStatus,
}

#[allow(clippy::too_many_arguments)]
fn control_loop(
    mut s: LoopState,
    period: Duration,
    opts: &DeployOptions,
    states: &LatestSlot<RobotState>,
    operator: &std::sync::mpsc::Receiver<OperatorAction>,
    cancel: &CancellationToken,
    publish_command: impl Fn(Vec<u8>) -> Result<(), DeployError>,
    publish_status: impl Fn(Vec<u8>) -> Result<(), DeployError>,
) -> Result<DeployStatus, DeployError> {
    let start = Instant::now();
    let secs = |t: Instant| t.saturating_duration_since(start).as_secs_f64();
    let mut pacer = Pacer::new(period);
    let mut period_error = Percentiles::new(STATS_WINDOW);
    let mut inference = Percentiles::new(STATS_WINDOW);
    let mut last_status = start;
    let mut stopping_since: Option<Instant> = None;
    let mut publish_errors = 0u64;
    loop {
        let (woke, since) = pacer.wait();
        if let Some(dt) = since {
            period_error.push((dt.as_secs_f64() - period.as_secs_f64()).abs() as f32 * 1e6);
        }
        let latest_copy = states.get();
        let latest = latest_copy.as_ref().map(|(state, at)| Latest {
            state,
            received_at: secs(*at),
        });
        let now = secs(woke);

        // Operator requests and stop conditions.
        while let Ok(action) = operator.try_recv() {
            match s.controller.operator(action, now, latest) {
                Ok(()) => info!(?action, mode = ?s.controller.mode(), "operator request applied"),
                Err(e) => warn!(?action, "operator request refused: {e}"),
            }
            if action == OperatorAction::Stop && stopping_since.is_none() {
                stopping_since = Some(woke);
            }
        }
        let out_of_time = opts.duration.is_some_and(|d| woke - start >= d);
        if (cancel.is_cancelled() || out_of_time) && stopping_since.is_none() {
            info!(
                "stopping: damping for {} s first",
                opts.safety.stop_damping_s
            );
            s.controller
                .operator(OperatorAction::Damp, now, latest)
                .ok();
            stopping_since = Some(woke);
        }

        let mode_before = s.controller.mode();
        let t0 = Instant::now();
        let mut out = s.controller.tick(now, latest, &mut s.policy);
        if out.inferred {
            inference.push(t0.elapsed().as_secs_f64() as f32 * 1e6);
        }
        out.command.stamp_ns = now_unix_ns();
        if let Some(f) = &out.new_fault {
            warn!(
                "DAMPING: {f} (send `l3p operate --robot-id {} resume` to continue)",
                opts.robot_id
            );
        }
        let sent = codec::encode(&out.command)
            .map_err(|e| DeployError::Config(e.to_string()))
            .and_then(&publish_command);
        match sent {
            Ok(()) => s.status.commands += 1,
            Err(e) => {
                publish_errors += 1;
                if publish_errors.is_power_of_two() {
                    warn!(errors = publish_errors, "could not publish a command: {e}");
                }
            }
        }
        s.status.ticks += 1;

        let mode = s.controller.mode();
        if mode != mode_before {
            info!(from = ?mode_before, to = ?mode, "mode change");
        }
        let finished =
            stopping_since.is_some_and(|t| (woke - t).as_secs_f32() >= opts.safety.stop_damping_s);
        if mode != mode_before || woke - last_status >= opts.status_every || finished {
            last_status = woke;
            s.status.mode = mode;
            s.status.fault = s.controller.fault().map(|f| f.to_string());
            s.status.overruns = pacer.overruns;
            s.status.rejected_states = states.rejected();
            (s.status.period_error_p50_us, s.status.period_error_p99_us) = period_error.p50_p99();
            (s.status.inference_p50_us, s.status.inference_p99_us) = inference.p50_p99();
            if let Some(why) = &opts.insecure {
                warn!(
                    "unauthenticated links (--insecure): {why}; anyone who reaches them can command this robot"
                );
            }
            if let Ok(json) = codec::encode_json(&s.status)
                && let Err(e) = publish_status(json)
            {
                warn!("could not publish status: {e}");
            }
        }
        if finished {
            return Ok(s.status);
        }
    }
}
