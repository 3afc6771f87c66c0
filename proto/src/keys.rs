//! Every Zenoh key expression of l3p is built here and nowhere else (DESIGN §4).
//!
//! ```text
//! l3p/<run>/rollout/<robot>/<actor>          rollout chunks (binary)
//! l3p/<run>/policy/announce                  policy announce (JSON)
//! l3p/<run>/policy/weights/<robot>/<version> queryable: weights blob (binary)
//! l3p/<run>/metrics/<source>                 metrics records (JSON)
//! l3p/<run>/actors/<robot>/<actor>           liveliness tokens
//! l3p/registry/<op>                          registry queryables
//! l3p/robot/<id>/state | command             deploy-time robot I/O (binary)
//! l3p/robot/<id>/operator                    operator requests to the deploy controller (binary)
//! l3p/robot/<id>/deploy/status               deploy controller status (JSON)
//! ```
//!
//! Names that become key segments (run, robot, actor, source, robot id) must pass
//! [`validate_segment`]; processes check them once at start-up, so the builders below are infallible.

/// Root of every key.
pub const ROOT: &str = "l3p";

/// A name that cannot be a key segment.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "invalid {what} name {name:?}: {reason}\nhint: use letters, digits, '-', '_' and '.', at most 64 characters"
)]
pub struct KeyError {
    pub what: &'static str,
    pub name: String,
    pub reason: &'static str,
}

/// Check that `name` is usable as one key segment: non-empty, at most 64 characters of
/// `[A-Za-z0-9_.-]`, not starting with `.` — so no `/`, wildcards (`*`, `**`), `$`, `?`, `#` or spaces.
pub fn validate_segment(what: &'static str, name: &str) -> Result<(), KeyError> {
    let fail = |reason| {
        Err(KeyError {
            what,
            name: name.to_string(),
            reason,
        })
    };
    if name.is_empty() {
        return fail("it is empty");
    }
    if name.len() > 64 {
        return fail("it is longer than 64 characters");
    }
    if name.starts_with('.') {
        return fail("it starts with '.'");
    }
    if !name
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
    {
        return fail("it contains a character other than letters, digits, '-', '_' and '.'");
    }
    Ok(())
}

/// `l3p/<run>/rollout/<robot>/<actor>`: where one actor publishes its chunks.
pub fn rollout(run: &str, robot: &str, actor: &str) -> String {
    format!("{ROOT}/{run}/rollout/{robot}/{actor}")
}

/// `l3p/<run>/rollout/**`: every rollout chunk of a run (the learner's subscription).
pub fn rollout_all(run: &str) -> String {
    format!("{ROOT}/{run}/rollout/**")
}

/// `l3p/<run>/policy/announce`.
pub fn policy_announce(run: &str) -> String {
    format!("{ROOT}/{run}/policy/announce")
}

/// `l3p/<run>/policy/weights/<robot>/<version>`: the key an actor queries for weights.
pub fn policy_weights(run: &str, robot: &str, version: u64) -> String {
    format!("{ROOT}/{run}/policy/weights/{robot}/{version}")
}

/// `l3p/<run>/policy/weights/**`: what the learner's weights queryable declares.
pub fn policy_weights_all(run: &str) -> String {
    format!("{ROOT}/{run}/policy/weights/**")
}

/// `l3p/<run>/metrics/<source>`.
pub fn metrics(run: &str, source: &str) -> String {
    format!("{ROOT}/{run}/metrics/{source}")
}

/// `l3p/<run>/metrics/**`: every metrics record of a run.
pub fn metrics_all(run: &str) -> String {
    format!("{ROOT}/{run}/metrics/**")
}

/// `l3p/<run>/actors/<robot>/<actor>`: an actor's liveliness token.
pub fn actor_liveliness(run: &str, robot: &str, actor: &str) -> String {
    format!("{ROOT}/{run}/actors/{robot}/{actor}")
}

/// `l3p/<run>/actors/**`: every actor of a run (liveliness subscription / get).
pub fn actors_all(run: &str) -> String {
    format!("{ROOT}/{run}/actors/**")
}

/// Parse `l3p/<run>/actors/<robot>/<actor>` back into `(robot, actor)`.
pub fn parse_actor_liveliness<'a>(run: &str, key: &'a str) -> Option<(&'a str, &'a str)> {
    let rest = key
        .strip_prefix(ROOT)?
        .strip_prefix('/')?
        .strip_prefix(run)?;
    let rest = rest.strip_prefix("/actors/")?;
    let (robot, actor) = rest.split_once('/')?;
    (!actor.contains('/')).then_some((robot, actor))
}

/// `l3p/registry/<op>`: one registry operation's queryable (`list`, `show`, `put`, `pull`, ...).
pub fn registry(op: &str) -> String {
    format!("{ROOT}/registry/{op}")
}

/// `l3p/registry/**`: what the registry service declares.
pub fn registry_all() -> String {
    format!("{ROOT}/registry/**")
}

/// `l3p/robot/<id>/state`.
pub fn robot_state(robot_id: &str) -> String {
    format!("{ROOT}/robot/{robot_id}/state")
}

/// `l3p/robot/<id>/command`.
pub fn robot_command(robot_id: &str) -> String {
    format!("{ROOT}/robot/{robot_id}/command")
}

/// `l3p/robot/<id>/operator`.
pub fn robot_operator(robot_id: &str) -> String {
    format!("{ROOT}/robot/{robot_id}/operator")
}

/// `l3p/robot/<id>/deploy/status`.
pub fn robot_deploy_status(robot_id: &str) -> String {
    format!("{ROOT}/robot/{robot_id}/deploy/status")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_follow_the_design_layout() {
        assert_eq!(rollout("r1", "a1", "0"), "l3p/r1/rollout/a1/0");
        assert_eq!(
            policy_weights("r1", "go1", 7),
            "l3p/r1/policy/weights/go1/7"
        );
        assert_eq!(actor_liveliness("r", "a1", "x"), "l3p/r/actors/a1/x");
        assert_eq!(robot_command("dog"), "l3p/robot/dog/command");
        assert_eq!(robot_operator("dog"), "l3p/robot/dog/operator");
        assert_eq!(robot_deploy_status("dog"), "l3p/robot/dog/deploy/status");
        assert_eq!(registry("list"), "l3p/registry/list");
    }

    #[test]
    fn liveliness_keys_parse_back() {
        let key = actor_liveliness("run-1", "anymal_c", "actor-3");
        assert_eq!(
            parse_actor_liveliness("run-1", &key),
            Some(("anymal_c", "actor-3"))
        );
        assert_eq!(parse_actor_liveliness("run-2", &key), None);
        assert_eq!(
            parse_actor_liveliness("run-1", "l3p/run-1/actors/a1/x/y"),
            None
        );
    }

    #[test]
    fn segments_reject_wildcards_and_separators() {
        for bad in [
            "",
            "a/b",
            "*",
            "**",
            "a b",
            "$x",
            "a?b",
            "#",
            ".hidden",
            &"x".repeat(65),
        ] {
            let err = validate_segment("run", bad).unwrap_err();
            assert!(err.to_string().contains("invalid run name"), "{err}");
        }
        for good in ["a1", "go2", "anymal_c", "run-2026.11.23", "X_9"] {
            validate_segment("robot", good).unwrap();
        }
    }
}
