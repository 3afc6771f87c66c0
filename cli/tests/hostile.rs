//! A hostile-input suite against live daemons over loopback Zenoh: `l3p registry serve` and `l3p
//! deploy` each get hundreds of malformed, wrong-version, oversized and well-formed-but-absurd
//! messages (the learner's share — bad rollout chunks — is in `e2e.rs`). Counted: attempts,
//! refusals, deaths. Every daemon must be alive afterwards and still do its job: the registry
//! serves a valid request, the controller never commands the robot on a rejected state and
//! counts every one of them.

use std::path::Path;
use std::time::Duration;

mod common;

use common::{Procs, deploy_endpoint, log_tails, wait_for_port};
use l3p_net::{ZenohSettings, free_loopback_port, open_session};
use l3p_proto::registry::{ErrorReply, OPS};
use l3p_proto::{
    ControlMode, DeployStatus, OperatorAction, OperatorCommand, RobotCommand, RobotState,
    WIRE_VERSION, codec, keys,
};

/// A small deterministic generator (xorshift), so a failure replays exactly.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn bytes(&mut self, max: usize) -> Vec<u8> {
        let len = self.below(max + 1);
        (0..len).map(|_| self.next() as u8).collect()
    }
}

/// Strings that are valid JSON string contents but odd as names and references.
const ODD: [&str; 9] = [
    "",
    "../../etc/passwd",
    "a1-core@",
    "@latest",
    "a1-core@999999999999999999999",
    "a1-core@-1",
    "\\u0000",
    "l3p/**",
    "名前@latest",
];

/// One hostile registry request: `(op, payload, attachment)`.
fn registry_request(rng: &mut Rng, k: usize) -> (String, Vec<u8>, Option<Vec<u8>>) {
    let v = WIRE_VERSION;
    let op = match rng.below(8) {
        0 => ["nope", "put/x/list", "LIST", "list/x", "show/extra"][rng.below(5)].to_string(),
        _ => OPS[rng.below(OPS.len())].to_string(),
    };
    let odd = ODD[rng.below(ODD.len())];
    let payload = match k % 6 {
        0 => rng.bytes(512),
        1 => format!(
            r#"{{"wire_version":{},"artifact":"a1-core@latest"}}"#,
            v + 1
        )
        .into_bytes(),
        2 => format!(r#"{{"wire_version":{v},"artifact":"{odd}","name":"{odd}","alias":"{odd}"}}"#)
            .into_bytes(),
        3 => format!(r#"{{"wire_version":{v},"kind":"{odd}","name":7,"robot":[]}}"#).into_bytes(),
        // Over the service's 64 KiB request limit (a blob may be larger: only for `put`).
        4 => vec![b'{'; 80 << 10],
        _ => {
            let mut valid =
                format!(r#"{{"wire_version":{v},"artifact":"a1-core@latest"}}"#).into_bytes();
            let at = rng.below(valid.len());
            valid.truncate(at);
            valid
        }
    };
    let attachment = (op == "put").then(|| match rng.below(3) {
        0 => rng.bytes(256),
        1 => format!(
            r#"{{"wire_version":{v},"spec":{{"name":"{odd}","kind":"core"}},"sha256":"00","size":{}}}"#,
            payload.len()
        )
        .into_bytes(),
        _ => format!(
            r#"{{"wire_version":{v},"spec":{{"name":"x","kind":"weights"}},"sha256":"00","size":1}}"#
        )
        .into_bytes(),
    });
    (op, payload, attachment)
}

/// One robot state the controller must reject (each has at least one defect).
fn bad_state(rng: &mut Rng, k: usize, robot_id: &str) -> Vec<u8> {
    let good = RobotState {
        wire_version: WIRE_VERSION,
        robot_id: robot_id.to_string(),
        seq: k as u64,
        stamp_ns: 1,
        base_quat: [1.0, 0.0, 0.0, 0.0],
        base_lin_vel: [0.0; 3],
        base_ang_vel: [0.0; 3],
        joint_pos: vec![0.0; 12],
        joint_vel: vec![0.0; 12],
        command: [0.0; 3],
    };
    let mut s = good.clone();
    match k % 9 {
        0 => return rng.bytes(400),
        1 => {
            let bytes = codec::encode(&good).unwrap();
            return bytes[..rng.below(bytes.len())].to_vec();
        }
        2 => s.wire_version += 1,
        3 => s.robot_id = "someone-else".into(),
        4 => s.joint_pos.truncate(11),
        5 => s.joint_vel[rng.below(12)] = f32::NAN,
        6 => s.base_quat = [0.0; 4],
        // Finite but physically absurd: the plausibility check's business.
        7 => s.joint_vel[rng.below(12)] = 1e30,
        _ => s.joint_pos[rng.below(12)] = 1e6,
    }
    codec::encode(&s).unwrap()
}

/// An operator message the controller must ignore (malformed, another robot, another version).
fn bad_operator(rng: &mut Rng, k: usize) -> Vec<u8> {
    let command = |robot_id: &str, wire_version: u32| OperatorCommand {
        wire_version,
        robot_id: robot_id.to_string(),
        action: OperatorAction::Stop,
        stamp_ns: 1,
    };
    match k % 3 {
        0 => rng.bytes(200),
        1 => codec::encode(&command("someone-else", WIRE_VERSION)).unwrap(),
        _ => codec::encode(&command("target", WIRE_VERSION + 1)).unwrap(),
    }
}

fn trained_policy() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs/a1-flat-session31/policy/policy.safetensors")
}

fn l3p(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_l3p"))
        .args(args)
        .output()
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn live_daemons_survive_hostile_input_and_count_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = d.join("registry");
    let out = l3p(&[
        "registry",
        "put",
        trained_policy().to_str().unwrap(),
        "--name",
        "a1-walk",
        "--kind",
        "deploy",
        "--robot",
        "a1",
        "--data",
        data.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    let mut procs = Procs(Vec::new());
    let port = free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    procs.spawn(
        "registry",
        &[
            "registry",
            "serve",
            "--data",
            data.to_str().unwrap(),
            "--listen",
            &endpoint,
        ],
        d,
    );
    wait_for_port(port, Duration::from_secs(60), "the registry", d);
    let (deploy_port, deploy_ep) = deploy_endpoint(port);
    procs.spawn(
        "deploy",
        &[
            "deploy",
            "--robot",
            "a1",
            "--robot-id",
            "target",
            "--policy",
            "a1-walk@latest",
            "--connect",
            &endpoint,
            "--listen",
            &deploy_ep,
        ],
        d,
    );
    wait_for_port(deploy_port, Duration::from_secs(60), "the controller", d);
    let session = open_session(&ZenohSettings::loopback(None, &[port, deploy_port]))
        .await
        .unwrap();

    // What the controller says and does, watched from the robot's side.
    let statuses = std::sync::Arc::new(std::sync::Mutex::new(Vec::<DeployStatus>::new()));
    let commands = std::sync::Arc::new(std::sync::Mutex::new(Vec::<ControlMode>::new()));
    let _status_sub = {
        let statuses = statuses.clone();
        session
            .declare_subscriber(keys::robot_deploy_status("target"))
            .callback(move |s| {
                if let Ok(st) = codec::decode_json::<DeployStatus>(&s.payload().to_bytes()) {
                    statuses.lock().unwrap().push(st);
                }
            })
            .await
            .unwrap()
    };
    let _command_sub = {
        let commands = commands.clone();
        session
            .declare_subscriber(keys::robot_command("target"))
            .callback(move |s| {
                if let Ok(c) = codec::decode::<RobotCommand>(&s.payload().to_bytes()) {
                    commands.lock().unwrap().push(c.mode);
                }
            })
            .await
            .unwrap()
    };

    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    // 1. The registry: every request answered (with data or an error reply), none unanswered.
    let attempts = 240;
    let (mut answered, mut refused, mut silent) = (0, 0, 0);
    for k in 0..attempts {
        let (op, payload, attachment) = registry_request(&mut rng, k);
        let get = session
            .get(keys::registry(&op))
            .payload(payload)
            .timeout(Duration::from_secs(10));
        let replies = match attachment {
            Some(a) => get.attachment(a).await,
            None => get.await,
        }
        .unwrap();
        match replies.recv_async().await {
            Ok(reply) => match reply.into_result() {
                Ok(_) => answered += 1,
                Err(e) => {
                    let error = codec::decode_json::<ErrorReply>(&e.payload().to_bytes());
                    assert!(
                        error.is_ok_and(|r| !r.message.is_empty()),
                        "request {k} ({op}): an error reply that says nothing"
                    );
                    refused += 1;
                }
            },
            // Only keys no queryable serves go unanswered (nested operations).
            Err(_) => silent += 1,
        }
    }

    // 2. The controller: bad states and operator messages, none of which it may act on. Its port
    // opens before it has fetched the policy and subscribed to states; states sent before then
    // reach no one. It subscribes before it publishes its first status, so wait for that.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while statuses.lock().unwrap().is_empty() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the controller never published a status{}",
            log_tails(d)
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let states = session
        .declare_publisher(keys::robot_state("target"))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .unwrap();
    let operator = session
        .declare_publisher(keys::robot_operator("target"))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
        .unwrap();
    let (bad_states, bad_operators) = (270, 90);
    for k in 0..bad_states {
        states.put(bad_state(&mut rng, k, "target")).await.unwrap();
        if k % 3 == 0 {
            operator.put(bad_operator(&mut rng, k / 3)).await.unwrap();
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    // The status (about once a second) catches up with every rejected state.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    let status = loop {
        let last = statuses.lock().unwrap().last().cloned();
        if let Some(s) = &last
            && s.rejected_states >= bad_states as u64
        {
            break s.clone();
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "rejections not counted: {last:?}{}",
            log_tails(d)
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };

    // 3. Deaths: none. Both daemons still do their job.
    let mut deaths = 0;
    for (name, child) in &mut procs.0 {
        if let Ok(Some(status)) = child.try_wait() {
            eprintln!("{name} died: {status}");
            deaths += 1;
        }
    }
    eprintln!(
        "hostile suite: registry {attempts} requests ({answered} answered, {refused} refused, \
         {silent} on keys nobody serves); controller {bad_states} bad states ({} rejected) and \
         {bad_operators} bad operator messages; {deaths} deaths",
        status.rejected_states
    );
    assert_eq!(deaths, 0, "{}", log_tails(d));
    assert_eq!(status.rejected_states, bad_states as u64, "{status:?}");
    assert_eq!(status.fault, None, "{status:?}");
    assert!(
        refused > attempts / 2 && silent < attempts / 4,
        "{answered} answered, {refused} refused, {silent} unanswered"
    );
    let sent = commands.lock().unwrap().clone();
    assert!(
        !sent
            .iter()
            .any(|m| matches!(m, ControlMode::Policy | ControlMode::Ramp)),
        "the controller acted on a rejected state: {sent:?}"
    );
    let out = l3p(&["registry", "show", "a1-walk@latest", "--connect", &endpoint]);
    assert!(
        out.status.success() && String::from_utf8_lossy(&out.stdout).contains("a1-walk"),
        "{out:?}"
    );
}
