//! The operator's side of `l3p/robot/<id>/operator` (`l3p operate`): [`operate`] sends an
//! [`OperatorAction`] to a running controller and sends it again until the controller's status
//! shows it in effect ([`action_took_effect`]), or fails with an [`OperateError`].
//!
//! Why resend: a request is a plain put, so one sent before the controller's subscriber is matched
//! (a controller just started, a link just re-established) is lost; applying a request twice is
//! harmless, because every action only moves the controller to a state it may already be in.

use std::time::Duration;

use l3p_proto::{
    ControlMode, DeployStatus, OperatorAction, OperatorCommand, WIRE_VERSION, codec, keys,
};

use crate::DeployError;

/// How long to wait for the status that confirms a request before sending it again.
pub const RESEND_AFTER: Duration = Duration::from_millis(400);

/// Why an operator request did not take effect.
#[derive(Debug, thiserror::Error)]
pub enum OperateError {
    #[error("{action:?} had no effect: controller {robot_id} is in {mode:?}{}", fault_suffix(.fault))]
    NoEffect {
        action: OperatorAction,
        robot_id: String,
        mode: ControlMode,
        fault: Option<String>,
    },
    #[error(
        "no deploy controller answered for robot id {robot_id} within {timeout:?}\nhint: is `l3p deploy --robot-id {robot_id}` running and connected to the same Zenoh network?"
    )]
    NoController { robot_id: String, timeout: Duration },
    #[error(transparent)]
    Deploy(#[from] DeployError),
}

fn fault_suffix(fault: &Option<String>) -> String {
    fault
        .as_ref()
        .map(|f| format!(" ({f})"))
        .unwrap_or_default()
}

/// `true` once `status` shows `action` in effect: resumed means ramping or running the policy,
/// damp and stop mean damping.
pub fn action_took_effect(action: OperatorAction, status: &DeployStatus) -> bool {
    match action {
        OperatorAction::Resume => matches!(status.mode, ControlMode::Ramp | ControlMode::Policy),
        OperatorAction::Damp | OperatorAction::Stop => status.mode == ControlMode::Damping,
    }
}

/// Sends `action` to controller `robot_id` every [`RESEND_AFTER`] until its status shows the action
/// in effect (that status is returned) or `timeout` passes.
pub async fn operate(
    session: &zenoh::Session,
    robot_id: &str,
    action: OperatorAction,
    timeout: Duration,
) -> Result<DeployStatus, OperateError> {
    keys::validate_segment("robot id", robot_id).map_err(|e| DeployError::Config(e.to_string()))?;
    let zenoh_err = |e: zenoh::Error| DeployError::Zenoh(e.to_string());
    let statuses = session
        .declare_subscriber(keys::robot_deploy_status(robot_id))
        .await
        .map_err(zenoh_err)?;
    let request = codec::encode(&OperatorCommand {
        wire_version: WIRE_VERSION,
        robot_id: robot_id.into(),
        action,
        stamp_ns: 0,
    })
    .map_err(|e| DeployError::Config(e.to_string()))?;
    let deadline = tokio::time::Instant::now() + timeout;
    let mut last: Option<DeployStatus> = None;
    while tokio::time::Instant::now() < deadline {
        session
            .put(keys::robot_operator(robot_id), request.clone())
            .await
            .map_err(zenoh_err)?;
        let resend =
            tokio::time::sleep_until(deadline.min(tokio::time::Instant::now() + RESEND_AFTER));
        tokio::pin!(resend);
        loop {
            tokio::select! {
                _ = &mut resend => break,
                sample = statuses.recv_async() => {
                    let Ok(sample) = sample else { break };
                    // Anything on the status key that is not a status is someone else's problem.
                    let Ok(status) = codec::decode_json::<DeployStatus>(&sample.payload().to_bytes())
                    else {
                        continue;
                    };
                    if action_took_effect(action, &status) {
                        return Ok(status);
                    }
                    last = Some(status);
                }
            }
        }
    }
    Err(match last {
        Some(status) => OperateError::NoEffect {
            action,
            robot_id: robot_id.into(),
            mode: status.mode,
            fault: status.fault,
        },
        None => OperateError::NoController {
            robot_id: robot_id.into(),
            timeout,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn status(mode: ControlMode) -> DeployStatus {
        DeployStatus {
            wire_version: WIRE_VERSION,
            robot_id: "dog".into(),
            robot: "a1".into(),
            policy: "a1-flat-a1@1".into(),
            mode,
            fault: None,
            ticks: 0,
            commands: 0,
            overruns: 0,
            rejected_states: 0,
            period_error_p50_us: 0.0,
            period_error_p99_us: 0.0,
            inference_p50_us: 0.0,
            inference_p99_us: 0.0,
            warning: None,
        }
    }

    #[test]
    fn each_action_is_confirmed_by_its_own_modes_only() {
        use ControlMode::*;
        let modes = [ZeroTorque, Ramp, Policy, Damping];
        let confirmed = |action| {
            modes
                .into_iter()
                .filter(|&m| action_took_effect(action, &status(m)))
                .collect::<Vec<_>>()
        };
        assert_eq!(confirmed(OperatorAction::Resume), [Ramp, Policy]);
        assert_eq!(confirmed(OperatorAction::Damp), [Damping]);
        assert_eq!(confirmed(OperatorAction::Stop), [Damping]);
    }

    #[test]
    fn a_request_without_effect_names_the_mode_and_fault() {
        let err = OperateError::NoEffect {
            action: OperatorAction::Resume,
            robot_id: "dog".into(),
            mode: ControlMode::Damping,
            fault: Some("state stale".into()),
        };
        assert_eq!(
            err.to_string(),
            "Resume had no effect: controller dog is in Damping (state stale)"
        );
    }
}
