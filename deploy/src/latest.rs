//! [`LatestSlot`]: a Zenoh subscriber that keeps only the newest valid robot message (state or
//! command) and when it arrived — never a queue, because an old state or command is worthless. Each
//! message is decoded, validated (joint count, finite values), checked for the robot id and by an
//! optional extra check (the controller's: a physically believable state) in the subscriber
//! callback; rejects are counted and logged at powers of two.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use l3p_proto::{RobotCommand, RobotState, ValidationError, WireMessage, codec};
use serde::de::DeserializeOwned;
use tracing::warn;

use crate::DeployError;

/// A message addressed to one robot.
pub trait RobotMessage: WireMessage + DeserializeOwned + Clone + Send + 'static {
    fn robot_id(&self) -> &str;
    fn validate(&self, num_joints: usize) -> Result<(), ValidationError>;
}

impl RobotMessage for RobotState {
    fn robot_id(&self) -> &str {
        &self.robot_id
    }
    fn validate(&self, num_joints: usize) -> Result<(), ValidationError> {
        RobotState::validate(self, num_joints)
    }
}

impl RobotMessage for RobotCommand {
    fn robot_id(&self) -> &str {
        &self.robot_id
    }
    fn validate(&self, num_joints: usize) -> Result<(), ValidationError> {
        RobotCommand::validate(self, num_joints)
    }
}

type Slot<T> = Arc<Mutex<Option<(T, Instant)>>>;

/// A check beyond decoding and validation (e.g. [`crate::observation::plausible_state`]).
pub type ExtraCheck<T> = Box<dyn Fn(&T) -> Result<(), String> + Send + Sync>;

/// The newest valid `T` on a key, with its receive time (monotonic clock of this process).
pub struct LatestSlot<T> {
    slot: Slot<T>,
    accepted: Arc<AtomicU64>,
    rejected: Arc<AtomicU64>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl<T: RobotMessage> LatestSlot<T> {
    /// Subscribe to `key`, accepting messages for `robot_id` with `num_joints` joints that pass
    /// `extra` too.
    pub async fn subscribe(
        session: &zenoh::Session,
        key: String,
        robot_id: &str,
        num_joints: usize,
        extra: Option<ExtraCheck<T>>,
    ) -> Result<Self, DeployError> {
        let slot: Slot<T> = Arc::new(Mutex::new(None));
        let accepted = Arc::new(AtomicU64::new(0));
        let rejected = Arc::new(AtomicU64::new(0));
        let (s, a, r) = (slot.clone(), accepted.clone(), rejected.clone());
        let robot_id = robot_id.to_string();
        let subscriber = session
            .declare_subscriber(key)
            .callback(move |sample| {
                let at = Instant::now();
                let checked = codec::decode::<T>(&sample.payload().to_bytes())
                    .map_err(|e| e.to_string())
                    .and_then(|m| {
                        m.validate(num_joints)
                            .map(|()| m)
                            .map_err(|e| e.to_string())
                    })
                    .and_then(|m| {
                        if m.robot_id() == robot_id {
                            Ok(m)
                        } else {
                            Err(format!("addressed to robot id {:?}", m.robot_id()))
                        }
                    })
                    .and_then(|m| match &extra {
                        Some(check) => check(&m).map(|()| m),
                        None => Ok(m),
                    });
                match checked {
                    Ok(m) => {
                        a.fetch_add(1, Ordering::Relaxed);
                        if let Ok(mut latest) = s.lock() {
                            *latest = Some((m, at));
                        }
                    }
                    Err(e) => {
                        let n = r.fetch_add(1, Ordering::Relaxed) + 1;
                        if n.is_power_of_two() {
                            warn!(rejected = n, "rejected {}: {e}", T::NAME);
                        }
                    }
                }
            })
            .await
            .map_err(|e| DeployError::Zenoh(e.to_string()))?;
        Ok(Self {
            slot,
            accepted,
            rejected,
            _subscriber: subscriber,
        })
    }

    /// A copy of the newest message and its receive time (the lock is held only for the copy).
    pub fn get(&self) -> Option<(T, Instant)> {
        self.slot.lock().ok().and_then(|l| l.clone())
    }

    pub fn accepted(&self) -> u64 {
        self.accepted.load(Ordering::Relaxed)
    }

    pub fn rejected(&self) -> u64 {
        self.rejected.load(Ordering::Relaxed)
    }
}

/// Sender clock for message stamps: nanoseconds since the Unix epoch.
pub fn now_unix_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}
