//! Fuzzing of the URDF loader and the quadruped inference on stable Rust (proptest): the catalog's
//! A1 file mutated (byte flips, cuts, duplicated spans, deep nesting, absurd numbers spliced into
//! attributes) must load or fail with an error naming the file — never panic, never overflow the
//! stack — and whatever loads must go through leg inference the same way. `L3P_FUZZ_CASES` raises
//! the case count for a long run (`cargo test --release -p l3p-robot --test fuzz_urdf`).

use l3p_robot::catalog::RobotSpec;
use l3p_robot::legs::infer_quadruped;
use l3p_robot::urdf::load_urdf_str;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

fn cases(default: u32) -> u32 {
    std::env::var("L3P_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Tokens that parse as numbers or markup but mean nothing sane in a robot description.
const TOKENS: [&str; 12] = [
    "1e300",
    "-1e38",
    "nan",
    "inf",
    "0",
    "-0.0",
    "1e-45",
    "\"",
    "<link name=\"x\">",
    "</joint>",
    "<![CDATA[",
    "&amp;&#0;",
];

fn mutate(text: &str, edits: &[(usize, u8, u8)]) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for &(at, byte, op) in edits {
        if bytes.is_empty() {
            break;
        }
        let at = at % bytes.len();
        match op % 10 {
            // Most edits keep the XML well-formed and change a number, so that the loader's
            // semantic checks (and the inference behind them) are reached, not only the parser's.
            0..=3 => {
                if let Some(k) = bytes[at..].iter().position(u8::is_ascii_digit) {
                    bytes[at + k] = b'0' + byte % 10;
                }
            }
            4 | 5 => {
                let token = TOKENS[byte as usize % TOKENS.len()].as_bytes();
                bytes.splice(at..at, token.iter().copied());
            }
            6 => {
                let end = (at + 40 * (byte as usize % 8)).min(bytes.len());
                let span = bytes[at..end].to_vec();
                bytes.splice(at..at, span);
            }
            7 => {
                let end = (at + byte as usize % 32).min(bytes.len());
                bytes.drain(at..end);
            }
            8 => bytes.truncate(at),
            _ => {
                // Deep nesting: far past the loader's depth limit.
                let depth = 50 + 200 * (byte as usize % 8);
                let open = "<a>".repeat(depth) + &"</a>".repeat(depth);
                bytes.splice(at..at, open.bytes());
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

#[test]
fn mutated_urdfs_load_or_fail_cleanly() {
    let a1 = RobotSpec::by_name("a1").unwrap().urdf;
    load_urdf_str(a1, "a1.urdf").expect("the unmutated seed loads");
    let strategy = prop::collection::vec((any::<usize>(), any::<u8>(), any::<u8>()), 1..6);
    let mut runner = TestRunner::new(Config {
        cases: cases(96),
        failure_persistence: None,
        ..Config::default()
    });
    let counts = std::cell::Cell::new((0u32, 0u32, 0u32));
    runner
        .run(&strategy, |edits| {
            let text = mutate(a1, &edits);
            let (loaded, quadruped, refused) = counts.get();
            match load_urdf_str(&text, "fuzz.urdf") {
                Ok(model) => {
                    let legs = infer_quadruped(&model).is_ok();
                    counts.set((loaded + 1, quadruped + u32::from(legs), refused));
                }
                Err(e) => {
                    prop_assert!(e.to_string().contains("fuzz.urdf"), "{e}");
                    counts.set((loaded, quadruped, refused + 1));
                }
            }
            Ok(())
        })
        .unwrap();
    let (loaded, quadruped, refused) = counts.get();
    eprintln!("fuzzed URDFs: {loaded} loaded ({quadruped} still a quadruped), {refused} refused");
    assert!(
        refused > 0 && loaded > 0,
        "the mutations were all of one kind"
    );
}
