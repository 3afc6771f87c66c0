//! Cross-crate tests of l3p live in `tests/`: the in-process pipeline (simulator → actor collector →
//! wire codec → learner) here; tests across real processes on loopback Zenoh live in
//! `cli/tests/` because Cargo gives only that package's tests the path of the `l3p` binary.
