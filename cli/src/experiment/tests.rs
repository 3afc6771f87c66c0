use super::*;

fn spec(text: &str) -> ExperimentSpec {
    let spec: ExperimentSpec = toml::from_str(text).unwrap();
    spec
}

const MICRO: &str = r#"
[experiment]
name = "micro"
base_config = "unused.toml"
data_dir = "/tmp/exp"
seeds = [1, 2]
envs = 8
[pretrain]
robots = ["a1"]
methods = ["mlp", "l3p"]
iterations = 30
[targets]
robots = ["go1", "anymal_c"]
methods = ["l3p", "l3p-transfer", "mlp-transfer"]
iterations = 20
terrain = "flat"
"#;

fn base() -> Config {
    let mut c = Config::default();
    c.actors = vec![ActorSpec {
        robot: "a1".into(),
        envs: 64,
        threads: 2,
    }];
    c
}

#[test]
fn plan_expands_pretraining_then_targets_with_their_dependencies() {
    let arms = plan(&spec(MICRO), &base()).unwrap();
    let names: Vec<&str> = arms.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(
        &names[..4],
        [
            "pretrain-mlp-s1",
            "pretrain-l3p-s1",
            "pretrain-mlp-s2",
            "pretrain-l3p-s2"
        ]
    );
    assert_eq!(arms.len(), 4 + 2 * 3 * 2);
    let t = arms
        .iter()
        .find(|a| a.name == "anymal-c-l3p-transfer-s2")
        .unwrap();
    assert_eq!(t.stage, Stage::Target);
    assert_eq!(t.depends_on.as_deref(), Some("pretrain-l3p-s2"));
    assert_eq!(t.config.ppo.mode, Mode::L3pTransfer);
    assert_eq!((t.config.run.seed, t.config.ppo.seed), (2, 2));
    assert_eq!(t.config.learner.max_iterations, 20);
    assert_eq!(t.config.actors[0].robot, "anymal_c");
    assert_eq!(
        (t.config.actors[0].envs, t.config.actors[0].threads),
        (8, 2)
    );
    assert_eq!(
        t.config.learner.init_from.as_deref(),
        Some(Path::new(
            "/tmp/exp/micro/pretrain-l3p-s2/pretrain-l3p-s2/checkpoints/latest.ckpt"
        ))
    );
    let m = arms
        .iter()
        .find(|a| a.name == "go1-mlp-transfer-s1")
        .unwrap();
    assert_eq!(m.depends_on.as_deref(), Some("pretrain-mlp-s1"));
    let scratch = arms.iter().find(|a| a.name == "go1-l3p-s1").unwrap();
    assert_eq!(scratch.depends_on, None);
    assert_eq!(scratch.config.learner.init_from, None);
    let p = &arms[0];
    assert_eq!((p.stage, p.iterations), (Stage::Pretrain, 30));
    assert_eq!(
        p.config.run.data_dir,
        Path::new("/tmp/exp/micro/pretrain-mlp-s1")
    );
    // Every arm's config survives the file it is written to.
    for arm in &arms {
        let text = toml::to_string(&arm.config).unwrap();
        let back: Config = toml::from_str(&text).unwrap();
        assert_eq!(back, arm.config, "{}", arm.name);
    }
}

const VARIANTS: &str = r#"
[[variants]]
name = "warm"
methods = ["l3p-transfer"]
robots = ["go1"]
transfer_heads = "prototype"

[[variants]]
name = "joint"
methods = ["l3p-transfer", "mlp-transfer"]
robots = ["anymal_c"]
pretrain_robots = ["a1", "go1"]
envs = 4

[[variants]]
name = "dz2"
pretrain_methods = ["l3p"]
d_z = 2
"#;

#[test]
fn variants_add_their_own_arms_and_pretrain_only_when_they_change_the_core() {
    let text = format!("{MICRO}{VARIANTS}");
    let arms = plan(&spec(&text), &base()).unwrap();
    let main = plan(&spec(MICRO), &base()).unwrap();
    // The main grid comes first and is untouched; each variant's arms follow in file order.
    assert_eq!(&arms[..main.len()], &main[..]);
    // warm: 1 robot × 1 method × 2 seeds; joint: 2 pretraining methods × 2 seeds + 1 robot
    // × 2 methods × 2 seeds; dz2: 1 pretraining method × 2 seeds.
    assert_eq!(arms.len(), main.len() + 2 + (4 + 4) + 2);
    let variants: Vec<&str> = arms[main.len()..]
        .iter()
        .map(|a| a.variant.as_deref().unwrap())
        .collect();
    let mut order = variants.clone();
    order.dedup();
    assert_eq!(order, ["warm", "joint", "dz2"]);
    let joint: Vec<Stage> = arms[main.len()..]
        .iter()
        .filter(|a| a.variant.as_deref() == Some("joint"))
        .map(|a| a.stage)
        .collect();
    assert!(joint.is_sorted_by_key(|s| *s == Stage::Target), "{joint:?}");

    // by_robot: pretraining first (the variants' own too), then every arm of one robot.
    let by_robot = plan(
        &spec(&text.replace("[experiment]\n", "[experiment]\nby_robot = true\n")),
        &base(),
    )
    .unwrap();
    assert_eq!(by_robot.len(), arms.len());
    let stages: Vec<Stage> = by_robot.iter().map(|a| a.stage).collect();
    assert!(
        stages.is_sorted_by_key(|s| *s == Stage::Target),
        "{stages:?}"
    );
    let robots: Vec<&str> = by_robot
        .iter()
        .filter(|a| a.stage == Stage::Target)
        .map(|a| a.robots[0].as_str())
        .collect();
    let mut runs = robots.clone();
    runs.dedup();
    let mut distinct = runs.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(
        runs.len(),
        distinct.len(),
        "each robot's arms together: {robots:?}"
    );

    let warm = arms
        .iter()
        .find(|a| a.name == "go1-l3p-transfer-warm-s2")
        .unwrap();
    assert_eq!(warm.variant.as_deref(), Some("warm"));
    assert_eq!(warm.depends_on.as_deref(), Some("pretrain-l3p-s2"));
    assert_eq!(warm.config.ppo.transfer_heads, TransferHeads::Prototype);
    let plain = arms
        .iter()
        .find(|a| a.name == "go1-l3p-transfer-s2")
        .unwrap();
    assert_eq!(plain.config.ppo.transfer_heads, TransferHeads::Fresh);

    let joint = arms
        .iter()
        .find(|a| a.name == "pretrain-joint-mlp-s1")
        .unwrap();
    assert_eq!(joint.robots, ["a1", "go1"]);
    assert_eq!(joint.config.actors.len(), 2);
    assert!(joint.config.actors.iter().all(|a| a.envs == 4));
    let t = arms
        .iter()
        .find(|a| a.name == "anymal-c-mlp-transfer-joint-s1")
        .unwrap();
    assert_eq!(t.depends_on.as_deref(), Some("pretrain-joint-mlp-s1"));
    // The variant's envs size its pretraining only: its target arms compare with the
    // from-scratch arms at the experiment's envs.
    assert_eq!(t.config.actors[0].envs, 8);

    let dz = arms
        .iter()
        .find(|a| a.name == "pretrain-dz2-l3p-s2")
        .unwrap();
    assert_eq!((dz.config.model.d_z, dz.config.model.d_h), (2, 64));
    assert_eq!(dz.robots, ["a1"]);
    assert!(
        !arms
            .iter()
            .any(|a| a.name.contains("dz2") && a.stage == Stage::Target)
    );
}

#[test]
fn bad_variants_are_refused() {
    let cases = [
        (
            VARIANTS.replace(r#"name = "joint""#, r#"name = "warm""#),
            "used twice",
        ),
        (
            VARIANTS.replace(r#"robots = ["go1"]"#, r#"robots = ["go7"]"#),
            "variants.warm",
        ),
        (
            VARIANTS.replace("d_z = 2", "d_z = 0"),
            "variants.dz2: d_h, d_z and envs",
        ),
        (
            VARIANTS
                .replace(
                    r#"pretrain_methods = ["l3p"]"#,
                    r#"pretrain_methods = ["mlp"]"#,
                )
                .replace("d_z = 2", "d_z = 2\nmethods = [\"l3p-transfer\"]"),
            "its pretraining has no l3p",
        ),
        (
            VARIANTS.replace(r#"methods = ["l3p-transfer"]"#, "methods = []"),
            "variants.warm: no arms",
        ),
    ];
    for (variants, want) in cases {
        let err = spec(&format!("{MICRO}{variants}")).validate().unwrap_err();
        assert!(err.contains(want), "{want}: {err}");
    }
    // A variant whose arm names collide with the main grid's.
    let clash = format!(
        "{MICRO}\n[[variants]]\nname = \"transfer\"\nmethods = [\"l3p\"]\nd_h = 8\npretrain_methods = [\"l3p\"]\n"
    );
    let err = plan(&spec(&clash), &base()).unwrap_err().to_string();
    assert!(
        err.contains("two arms are named") && err.contains("-l3p-transfer-s1"),
        "{err}"
    );
}

/// A stage on the base config's own terrain preset keeps the recipe's terrain tuning; another
/// preset starts from its defaults but keeps the heightfield edge fix.
#[test]
fn a_stage_on_the_base_preset_keeps_the_recipes_terrain() {
    let mut base = base();
    base.env.terrain.preset = TerrainPreset::Curriculum;
    base.env.terrain.boxes_height = Some([0.025, 0.1]);
    base.env.terrain.fix_internal_edges = true;
    base.env.height_scan = true;
    let text = MICRO.replace(
        "iterations = 30\n",
        "iterations = 30\nterrain = \"curriculum\"\n",
    );
    let text = text.replace(r#"terrain = "flat""#, r#"terrain = "simple-rough""#);
    let arms = plan(&spec(&text), &base).unwrap();
    let pretrain = arms.iter().find(|a| a.stage == Stage::Pretrain).unwrap();
    assert_eq!(pretrain.config.env.terrain, base.env.terrain);
    let target = arms.iter().find(|a| a.stage == Stage::Target).unwrap();
    let terrain = &target.config.env.terrain;
    assert_eq!(terrain.preset, TerrainPreset::SimpleRough);
    assert_eq!(terrain.boxes_height, None);
    assert!(terrain.fix_internal_edges);
}

/// An ablation pretrains only: `[targets]` empty as a whole, the variants' cores as arms.
#[test]
fn an_experiment_without_targets_plans_only_pretraining() {
    let text = MICRO
        .replace(r#"robots = ["go1", "anymal_c"]"#, "robots = []")
        .replace(
            r#"methods = ["l3p", "l3p-transfer", "mlp-transfer"]"#,
            "methods = []",
        )
        + "[[variants]]\nname = \"dh8\"\npretrain_methods = [\"l3p\"]\nd_h = 8\n";
    let spec = spec(&text);
    spec.validate().unwrap();
    let arms = plan(&spec, &base()).unwrap();
    // 2 methods × 2 seeds of the main pretraining, then dh8's l3p core × 2 seeds.
    assert_eq!(arms.len(), 6);
    assert!(arms.iter().all(|a| a.stage == Stage::Pretrain), "{arms:?}");
    assert_eq!(
        arms.iter()
            .filter(|a| a.variant.as_deref() == Some("dh8"))
            .count(),
        2
    );
}

#[test]
fn bad_specs_are_refused_with_the_key_named() {
    let cases = [
        (MICRO.replace("seeds = [1, 2]", "seeds = [1, 1]"), "repeats"),
        (
            MICRO.replace("seeds = [1, 2]", "seeds = []"),
            "experiment.seeds",
        ),
        (
            MICRO.replace(r#"methods = ["mlp", "l3p"]"#, r#"methods = ["l3p"]"#),
            "pretrain.methods has no mlp",
        ),
        (
            MICRO.replace(
                r#"methods = ["mlp", "l3p"]"#,
                r#"methods = ["l3p-transfer"]"#,
            ),
            "not a from-scratch method",
        ),
        (MICRO.replace(r#""go1""#, r#""go7""#), "targets.robots"),
        (
            MICRO.replace("iterations = 20", "iterations = 0"),
            "targets.iterations",
        ),
        (
            MICRO.replace(r#"name = "micro""#, r#"name = "a/b""#),
            "experiment.name",
        ),
        (
            MICRO.replace(r#"robots = ["go1", "anymal_c"]"#, "robots = []"),
            "targets.robots and targets.methods must not be empty",
        ),
    ];
    for (text, want) in cases {
        let err = spec(&text).validate().unwrap_err();
        assert!(err.contains(want), "{want}: {err}");
    }
    assert!(toml::from_str::<ExperimentSpec>(&MICRO.replace("envs = 8", "envz = 8")).is_err());
}

#[test]
fn mean_std_and_bands_over_seeds() {
    assert_eq!(mean_std(&[]), None);
    assert_eq!(mean_std(&[2.0]), Some((2.0, 0.0)));
    let (m, s) = mean_std(&[1.0, 2.0, 3.0, f64::NAN]).unwrap();
    assert!((m - 2.0).abs() < 1e-12 && (s - 1.0).abs() < 1e-12);
    let b = band(&[
        vec![(1.0, 1.0), (2.0, 2.0), (3.0, 5.0)],
        vec![(1.0, 3.0), (2.0, 4.0)],
    ]);
    // Iteration 3 is left out: only one seed reached it.
    assert_eq!(b, vec![(1.0, 2.0, 1.0, 3.0), (2.0, 3.0, 2.0, 4.0)]);
}

fn result(robot: &str, method: Mode, seed: u64, reward_85: Option<u64>, reward: f64) -> ArmResult {
    ArmResult {
        robot: robot.into(),
        method,
        variant: None,
        seed,
        row: ReportRow {
            iterations: 100,
            level_85: None,
            level_95: None,
            reward_85,
            reward_95: reward_85.map(|v| v + 10),
            final_level: 0.0,
            final_reward: reward,
            lin_vel_error: 0.1,
            yaw_rate_error: 0.2,
        },
        wall_seconds: 120.0,
        eval_lin_vel_error: 0.15,
        eval_yaw_rate_error: 0.25,
        eval_return: reward,
        zero_shot_return: (method == Mode::L3pTransfer).then_some(1.5),
        reward_for_bars: Vec::new(),
        terrain_levels: false,
        terrain_reach: BTreeMap::new(),
        zero_shot_reach: None,
        walk: None,
        zero_shot_walk: None,
    }
}

#[test]
fn the_table_has_one_row_per_robot_and_method_with_the_spread_over_seeds() {
    let table = markdown_table(&[
        result("go1", Mode::L3pTransfer, 1, Some(40), 20.0),
        result("go1", Mode::L3pTransfer, 2, Some(60), 22.0),
        result("go1", Mode::Mlp, 1, Some(100), 18.0),
        result("go1", Mode::Mlp, 2, None, 16.0),
    ]);
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("| go1")).collect();
    assert_eq!(rows.len(), 2, "{table}");
    let transfer = rows.iter().find(|r| r.contains("l3p-transfer")).unwrap();
    // Reward 85%: mean 50 ± std 14 (sample std of 40, 60); final reward 21.00 ± 1.41; the
    // paper's Go1 L3P-Transfer reward convergence 181 / 234.
    assert!(transfer.contains("| 50 ± 14 |"), "{transfer}");
    assert!(transfer.contains("| 21.00 ± 1.41 |"), "{transfer}");
    assert!(transfer.contains("| 1.50 ± 0.00 |"), "{transfer}");
    assert!(transfer.contains("| 181 / 234 |"), "{transfer}");
    let mlp = rows.iter().find(|r| r.contains("| mlp |")).unwrap();
    assert!(mlp.contains("100 ± 0 (1/2 reached)"), "{mlp}");
    assert!(mlp.contains("| 2.0 ± 0.0 |"), "{mlp}"); // wall minutes
    // On flat ground the level columns are empty; a transfer arm's reward is compared with
    // the same architecture from scratch (no l3p scratch arm here).
    assert!(mlp.contains("| — (flat) | — (flat) | — (flat) |"), "{mlp}");
    assert!(transfer.contains("| 21.00 ± 1.41 | — |"), "{transfer}");
    let with_scratch = markdown_table(&[
        result("go1", Mode::L3pTransfer, 1, Some(40), 21.0),
        result("go1", Mode::L3p, 1, Some(90), 14.0),
    ]);
    assert!(
        with_scratch.contains("| 21.00 ± 0.00 | 150% |"),
        "{with_scratch}"
    );
    // A variant's transfer row: its own row, compared with the main grid's scratch arms, and
    // no paper numbers (the paper has no such arm).
    let mut warm = result("go1", Mode::L3pTransfer, 1, Some(30), 28.0);
    warm.variant = Some("warm".into());
    let with_variant = markdown_table(&[
        warm,
        result("go1", Mode::L3pTransfer, 1, Some(40), 21.0),
        result("go1", Mode::L3p, 1, Some(90), 14.0),
    ]);
    let row = with_variant
        .lines()
        .find(|l| l.contains("l3p-transfer [warm]"))
        .unwrap();
    assert!(row.contains("| 28.00 ± 0.00 | 200% |"), "{row}");
    assert!(row.ends_with("| — |"), "{row}");
    assert_eq!(
        with_variant
            .lines()
            .filter(|l| l.starts_with("| go1"))
            .count(),
        3
    );
}

#[test]
fn terrain_reach_is_tabled_per_type_and_evaluated_on_one_type_with_the_curriculum() {
    let mut a = result("go1", Mode::L3pTransfer, 1, Some(40), 20.0);
    a.terrain_reach = [("flat".to_string(), 6.0), ("boxes".to_string(), 2.0)].into();
    let mut b = result("go1", Mode::L3pTransfer, 2, Some(40), 20.0);
    b.terrain_reach = [("flat".to_string(), 8.0)].into();
    let plain = result("go1", Mode::Mlp, 1, Some(40), 20.0);
    // Zero-shot: the pretrained policy before fine-tuning, once per pretraining arm (two arms
    // from pretrain-l3p-s1 share it; seed 2 started from pretrain-l3p-s2).
    let zero_shot = |source: &str, flat: f64| {
        Some(ZeroShotReach {
            source: source.into(),
            source_label: "l3p".into(),
            levels: [("flat".to_string(), flat)].into(),
        })
    };
    a.zero_shot_reach = zero_shot("pretrain-l3p-s1", 3.0);
    b.zero_shot_reach = zero_shot("pretrain-l3p-s2", 5.0);
    let mut warm = result("go1", Mode::L3pTransfer, 1, Some(40), 20.0);
    warm.variant = Some("warm".into());
    warm.terrain_reach = [("flat".to_string(), 9.0)].into();
    warm.zero_shot_reach = zero_shot("pretrain-l3p-s1", 3.0);
    let types = [
        TerrainType::Flat,
        TerrainType::Boxes,
        TerrainType::PyramidSlope,
    ];
    let results = [a, b, plain, warm];
    let table = terrain_reach_table(&results, &types);
    assert!(table.starts_with("| robot | method | seeds | flat | boxes | pyramid_slope |"));
    // Mean ± sample std over the seeds that have the type; none: a dash. Arms without terrain
    // evaluations get no row.
    assert!(
        table.contains("| go1 | l3p-transfer | 2 | 7.00 ± 1.41 | 2.00 ± 0.00 | — |"),
        "{table}"
    );
    assert!(!table.contains("| mlp |"), "{table}");
    assert!(
        table.contains("| go1 | zero-shot l3p | 2 | 4.00 ± 1.41 | — | — |"),
        "{table}"
    );
    assert!(
        table.contains("| go1 | l3p-transfer [warm] | 1 | 9.00 ± 0.00 |"),
        "{table}"
    );
    let groups = terrain_reach_groups(&results);
    let zs = &groups[&("go1".to_string(), "zero-shot l3p".to_string())];
    assert_eq!(mean_reach(zs, &types)[0], 4.0);
    assert!(mean_reach(zs, &types)[1].is_nan());

    let mut env = l3p_task::config::EnvConfig::default();
    env.terrain.preset = TerrainPreset::SimpleRough;
    let one = single_terrain_env(&env, TerrainType::Boxes);
    assert_eq!(one.terrain.preset, TerrainPreset::Curriculum);
    assert_eq!(one.terrain.curriculum, Some(true));
    let spec = one.terrain.resolve("go1").unwrap();
    assert_eq!(
        spec.proportions,
        l3p_task::terrain::TypeProportions::only(TerrainType::Boxes)
    );
    env.terrain.preset = TerrainPreset::Paper;
    assert_eq!(
        single_terrain_env(&env, TerrainType::Flat).terrain.preset,
        TerrainPreset::Paper
    );
}

#[test]
fn time_to_scratch_counts_iterations_to_the_scratch_final_and_marks_bounds() {
    // A ramp to `top` reached at iteration `at`, flat afterwards, over 100 iterations.
    let ramp = |at: f64, top: f64| -> Vec<(f64, f64)> {
        (1..=100)
            .map(|i| (i as f64, top * (i as f64 / at).min(1.0)))
            .collect()
    };
    let arm = |method, variant: Option<&str>, seed, at, top| {
        let mut r = result("go1", method, seed, Some(40), top);
        r.variant = variant.map(String::from);
        r.reward_for_bars = ramp(at, top);
        r
    };
    let results = [
        // From scratch: final reward 20 (both seeds), reached at 80 and 100.
        arm(Mode::L3p, None, 1, 80.0, 20.0),
        arm(Mode::L3p, None, 2, 100.0, 20.0),
        // Transfer: 20 at 30 and 60 → 45 against 90: 2×.
        arm(Mode::L3pTransfer, None, 1, 30.0, 20.0),
        arm(Mode::L3pTransfer, None, 2, 60.0, 20.0),
        // A variant that ends at 15 never reaches 20: counted as 100 → a bound.
        arm(Mode::L3pTransfer, Some("warm"), 1, 10.0, 15.0),
        // No `mlp` arm: the MLP family has no bar, `mlp-transfer` gets no row.
        arm(Mode::MlpTransfer, None, 1, 10.0, 30.0),
    ];
    let table = time_to_scratch_table(&results, 1.0);
    assert!(
        table.contains("| go1 | l3p | 20.00 | 90 | 80, 100 |  |"),
        "{table}"
    );
    assert!(
        table.contains("| go1 | l3p-transfer | 20.00 | 45 | 30, 60 | 2.00× |"),
        "{table}"
    );
    assert!(
        table.contains("| go1 | l3p-transfer [warm] | 20.00 | ≥ 100 | — | ≤ 0.90× |"),
        "{table}"
    );
    assert!(!table.contains("mlp-transfer"), "{table}");
    // Half the bar: reached at half the ramp.
    let half = time_to_scratch_table(&results, 0.5);
    assert!(
        half.contains("| go1 | l3p | 10.00 | 45 | 40, 50 |  |"),
        "{half}"
    );
    // No from-scratch arm at all: nothing to measure against.
    assert!(time_to_scratch_table(&results[2..], 1.0).is_empty());
}

/// A walk check line as `l3p train --until-walks` appends it (one 1.0 m/s row).
fn check_line(iteration: u64, failures: &[&str]) -> String {
    serde_json::json!({
        "iteration": iteration,
        "rows": [{"forward": 1.0, "walk_failures": failures}],
    })
    .to_string()
}

fn write_run(dir: &Path, walk: serde_json::Value, checks: &[String]) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("walk.json"), walk.to_string()).unwrap();
    std::fs::write(dir.join("walk_checks.jsonl"), checks.join("\n") + "\n").unwrap();
}

#[test]
fn until_walks_bookkeeping_walked_never_walked_and_interrupted() {
    let tmp = tempfile::tempdir().unwrap();
    // Walks at its first check: samples from walk.json, wall-clock over every attempt.
    let first = tmp.path().join("first");
    write_run(
        &first,
        serde_json::json!({"walks": true, "iteration": 25, "samples": 307_200, "wall_clock_s": 80.0, "rows": []}),
        &[check_line(25, &[])],
    );
    let WalkProgress::Settled(w) = walk_progress(&first, 27, 300, 12_288, 20.0) else {
        panic!("a walked arm is settled");
    };
    assert!(w.walks);
    assert_eq!(w.gait, Some((25, 25 * 12_288)));
    assert_eq!(w.tracks, Some((25, 25 * 12_288)));
    assert_eq!((w.iteration, w.samples, w.checks), (25, 307_200, 1));
    assert_eq!(w.wall_seconds, Some(100.0));
    // Never walks: at the cap it is settled as "not within the cap", samples a lower bound, the
    // last check's failures kept.
    let never = tmp.path().join("never");
    write_run(
        &never,
        serde_json::json!({"walks": false}),
        &[
            check_line(25, &["xy tracking error 0.992 > 0.200 m/s", "falls"]),
            check_line(50, &["heading changes 40° per episode (want <= 15°)"]),
        ],
    );
    let WalkProgress::Settled(w) = walk_progress(&never, 60, 60, 1_000, 0.0) else {
        panic!("an arm at its cap is settled");
    };
    assert!(!w.walks);
    assert_eq!(
        (w.iteration, w.last_check, w.samples, w.checks),
        (60, 50, 60_000, 2)
    );
    assert!(w.failures[0].contains("heading"), "{:?}", w.failures);
    assert_eq!(
        w.gait,
        Some((50, 50_000)),
        "its gait held but for the heading at 50"
    );
    assert_eq!(w.tracks, Some((50, 50_000)), "it tracked from 50 on");
    assert_eq!(w.wall_seconds, None);
    // Interrupted before the cap (its trainer writes walks: false on the way out): resume, and
    // the check history stays for the resumed run to append to.
    let cut = tmp.path().join("cut");
    write_run(
        &cut,
        serde_json::json!({"walks": false}),
        &[check_line(25, &["falls"])],
    );
    assert_eq!(
        walk_progress(&cut, 31, 300, 1_000, 0.0),
        WalkProgress::Interrupted { iteration: 31 }
    );
    let mut checks = std::fs::read_to_string(cut.join("walk_checks.jsonl")).unwrap();
    checks.push_str(&(check_line(50, &[]) + "\n"));
    std::fs::write(cut.join("walk_checks.jsonl"), checks).unwrap();
    std::fs::write(
        cut.join("walk.json"),
        serde_json::json!({"walks": true, "iteration": 50, "samples": 50_000, "wall_clock_s": 30.0}).to_string(),
    )
    .unwrap();
    let WalkProgress::Settled(w) = walk_progress(&cut, 52, 300, 1_000, 45.0) else {
        panic!("walked after the resume");
    };
    assert_eq!(
        (w.iteration, w.checks),
        (50, 2),
        "the check before the interruption is kept"
    );
    assert_eq!(w.wall_seconds, Some(75.0));
}

fn walked(robot: &str, method: Mode, seed: u64, samples: Option<u64>) -> ArmResult {
    let mut r = result(robot, method, seed, None, 1.0);
    r.walk = Some(WalkOutcome {
        walks: samples.is_some(),
        iteration: samples.map_or(300, |s| s / 1_000),
        last_check: 0,
        samples: samples.unwrap_or(300_000),
        wall_seconds: None,
        failures: Vec::new(),
        checks: 1,
        gait: samples.map(|s| (s / 2_000, s / 2)),
        tracks: samples.map(|s| (s / 4_000, s / 4)),
        rows: Vec::new(),
    });
    r
}

#[test]
fn samples_to_walk_medians_ratios_and_bounds() {
    assert_eq!(
        censored_median(&[(3.0, false), (1.0, false), (2.0, true)]),
        Some(CensoredMedian {
            value: 2.0,
            at_least: true
        })
    );
    assert_eq!(
        censored_median(&[(3.0, true), (1.0, false), (2.0, false)]),
        Some(CensoredMedian {
            value: 2.0,
            at_least: false
        })
    );
    let results = vec![
        walked("go1", Mode::L3p, 1, Some(200_000)),
        walked("go1", Mode::L3p, 2, Some(180_000)),
        walked("go1", Mode::L3p, 3, None),
        walked("go1", Mode::L3pTransfer, 1, Some(20_000)),
        walked("go1", Mode::L3pTransfer, 2, Some(40_000)),
        walked("go1", Mode::L3pTransfer, 3, Some(30_000)),
        walked("spot", Mode::L3p, 1, Some(100_000)),
        walked("spot", Mode::L3pTransfer, 1, None),
    ];
    let t = samples_to_walk_table(&results);
    let row = |robot: &str, method: &str| -> String {
        t.lines()
            .find(|l| l.starts_with(&format!("| {robot} | {method} |")))
            .unwrap_or_else(|| panic!("no {robot} {method} row in\n{t}"))
            .to_string()
    };
    // Scratch: 2 of 3 walked, the third counts as its cap and decides nothing (median 0.20).
    let scratch = row("go1", "l3p");
    assert!(
        scratch.contains("| 2/3 |") && scratch.contains("| 0.20 |"),
        "{scratch}"
    );
    assert!(scratch.contains("0.18–>0.30"), "{scratch}");
    // Samples to track, then to the gait without the heading bound: 0.05 M, then 0.10 M.
    assert!(
        t.lines()
            .next()
            .unwrap()
            .contains("| tracking (xy error within its bound)"),
        "{t}"
    );
    assert!(scratch.contains("| 0.05, 1× | 0.10, 1× |"), "{scratch}");
    // Transfer: 0.03 M against 0.20 M.
    let transfer = row("go1", "l3p-transfer");
    assert!(
        transfer.contains("| 3/3 |") && transfer.contains("| 0.15× |"),
        "{transfer}"
    );
    // A transfer arm that did not walk: its median is a lower bound, and so is the ratio.
    let spot = row("spot", "l3p-transfer");
    assert!(
        spot.contains("| 0/1 |") && spot.contains("≥ 3.00×"),
        "{spot}"
    );
    assert!(samples_to_walk_table(&[result("go1", Mode::L3p, 1, None, 1.0)]).is_empty());
}
