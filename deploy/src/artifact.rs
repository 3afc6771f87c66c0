//! Loading a deploy artifact and refusing it before any command is sent when it does not fit the
//! robot: [`load_policy`] checks the hash, the robot name, the dimensions, the joint order and the
//! observation layout, and fills in the I/O contract from the catalog for exports made before it
//! travelled with the weights.

use std::path::Path;

use l3p_infer::{DeployPolicy, RobotIo};
use l3p_proto::registry::{ArtifactKind, ArtifactMeta};
use l3p_registry_client::RegistryClient;
use l3p_robot::catalog::RobotSpec;
use l3p_task::config::EnvConfig;
use l3p_task::contract::{env_for_policy, robot_io};

use crate::DeployError;
use crate::observation::{ObservationBuilder, standing_state};

/// A policy checked against its robot, ready to arm.
#[derive(Debug, Clone)]
pub struct LoadedPolicy {
    /// `name@version`, or the file path it was read from.
    pub reference: String,
    pub sha256: String,
    pub policy: DeployPolicy,
    pub io: RobotIo,
    pub action_scale: f32,
    /// The export had no `io` and it was rebuilt from this build's robot catalog.
    pub io_from_catalog: bool,
}

/// Parse and check an export blob for `robot`. `expected_sha256` (from the registry's metadata) is
/// compared with the bytes' hash.
pub fn load_policy(
    reference: &str,
    bytes: &[u8],
    expected_sha256: Option<&str>,
    robot: &RobotSpec,
) -> Result<LoadedPolicy, DeployError> {
    let sha256 = l3p_registry_client::sha256_hex(bytes);
    if let Some(expected) = expected_sha256
        && expected != sha256
    {
        return Err(DeployError::Integrity {
            reference: reference.into(),
            expected: expected.into(),
            actual: sha256,
        });
    }
    let policy = DeployPolicy::from_bytes(bytes)
        .map_err(|e| DeployError::Policy(format!("{reference}: {e}")))?;
    let config = &policy.config;
    if config.robot != robot.name {
        return Err(DeployError::WrongRobot {
            reference: reference.into(),
            policy_robot: config.robot.clone(),
            robot: robot.name.into(),
        });
    }
    let joints = robot.joint_names.len();
    if config.action_dim != joints {
        return Err(DeployError::Policy(format!(
            "{reference}: action_dim {} but {} has {joints} joints",
            config.action_dim, robot.name
        )));
    }
    if !(config.action_scale.is_finite() && config.action_scale > 0.0) {
        return Err(DeployError::Policy(format!(
            "{reference}: action_scale {} is not > 0",
            config.action_scale
        )));
    }
    let (io, io_from_catalog) = match &config.io {
        Some(io) => (io.clone(), false),
        None => {
            let env = env_for_policy(&EnvConfig::default(), config.obs_dim, None);
            let io = robot_io(robot, &env).map_err(|e| DeployError::Robot(e.to_string()))?;
            (io, true)
        }
    };
    io.check(config.obs_dim, config.action_dim)
        .map_err(|e| DeployError::Policy(format!("{reference}: {e}")))?;
    let names: Vec<&str> = io.joint_names.iter().map(String::as_str).collect();
    if names != robot.joint_names {
        return Err(DeployError::Policy(format!(
            "{reference}: joint order {names:?} differs from {}'s {:?}",
            robot.name, robot.joint_names
        )));
    }
    let builder = ObservationBuilder::new(&io)
        .map_err(|e| DeployError::Policy(format!("{reference}: {e}")))?;
    let loaded = LoadedPolicy {
        reference: reference.into(),
        sha256,
        action_scale: config.action_scale,
        policy,
        io,
        io_from_catalog,
    };
    // A policy that is already non-finite at the nominal standing pose will be damped at once;
    // say so before arming rather than after.
    let mut obs = vec![0.0; builder.obs_dim()];
    builder.build(
        &standing_state(&loaded.io, "check"),
        &vec![0.0; joints],
        0,
        &mut obs,
    );
    let finite = loaded
        .policy
        .act(&obs)
        .is_ok_and(|a| a.iter().all(|v| v.is_finite()));
    if !finite {
        tracing::warn!(
            policy = reference,
            "the policy's action at the standing pose is not finite; the watchdog will damp"
        );
    }
    Ok(loaded)
}

/// Fetch `reference` (`name@version|alias`) from the registry (hash checked by the client and
/// again here) and check it for `robot`.
pub async fn fetch_policy(
    client: &RegistryClient,
    reference: &str,
    robot: &RobotSpec,
) -> Result<(ArtifactMeta, LoadedPolicy), DeployError> {
    let (meta, bytes) = client
        .get_blob(reference)
        .await
        .map_err(|e| DeployError::Registry(e.to_string()))?;
    if meta.kind != ArtifactKind::Deploy {
        return Err(DeployError::Policy(format!(
            "{} is a {} artifact, not a deploy artifact\nhint: learners publish deploy artifacts \
             as <run>-<robot>; or make one with `l3p export`",
            meta.reference(),
            meta.kind.as_str()
        )));
    }
    if let Some(r) = &meta.robot
        && r != robot.name
    {
        return Err(DeployError::WrongRobot {
            reference: meta.reference(),
            policy_robot: r.clone(),
            robot: robot.name.into(),
        });
    }
    let loaded = load_policy(&meta.reference(), &bytes, Some(&meta.sha256), robot)?;
    Ok((meta, loaded))
}

/// Read an export from a file (`*.safetensors`) or a directory holding `policy.safetensors`.
pub fn read_policy_file(path: &Path, robot: &RobotSpec) -> Result<LoadedPolicy, DeployError> {
    let file = if path.is_dir() {
        path.join("policy.safetensors")
    } else {
        path.to_path_buf()
    };
    let bytes = std::fs::read(&file).map_err(|source| DeployError::Io {
        path: file.display().to_string(),
        source,
    })?;
    load_policy(&file.display().to_string(), &bytes, None, robot)
}
