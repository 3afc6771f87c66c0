use super::*;
use crate::config::{TerrainConfig, TerrainPreset};

fn small_spec(preset: TerrainPreset) -> TerrainSpec {
    let mut c = TerrainConfig::with_preset(preset);
    c.border_width = 2.0;
    c.horizontal_resolution = 0.05;
    c.resolve("anymal_c").unwrap()
}

#[test]
fn isaaclab_column_types() {
    let p = TypeProportions::isaaclab_rough();
    let types: Vec<_> = (0..20).map(|c| p.column_type(c, 20)).collect();
    use TerrainType::*;
    let expected = [
        [PyramidStairs; 4].as_slice(),
        &[InvertedPyramidStairs; 4],
        &[Boxes; 4],
        &[RandomRough; 4],
        &[PyramidSlope; 2],
        &[InvertedPyramidSlope; 2],
    ]
    .concat();
    assert_eq!(types, expected);
}

#[test]
fn stairs_heights_match_formula() {
    let p = SubTerrainParams::isaaclab_rough();
    let l = 8.0;
    // (8 - 2 - 3) // 0.6 + 1 = 6 rings, platform 6 - 3.6 = 2.4 m.
    assert_eq!(stairs_num_steps(&p, l), 6);
    let d = 0.5;
    let h = 0.05 + 0.5 * 0.18;
    let n = TileNoise::default();
    let z = |u: f32, v: f32| tile_height(TerrainType::PyramidStairs, &p, l, d, &n, u, v);
    assert_eq!(z(0.5, 4.0), 0.0, "border is flat");
    assert!((z(1.15, 4.0) - h).abs() < 1e-6, "first ring");
    assert!((z(1.45, 4.0) - 2.0 * h).abs() < 1e-6, "second ring");
    assert!((z(2.65, 4.0) - 6.0 * h).abs() < 1e-6, "last ring");
    assert!((z(4.0, 4.0) - 7.0 * h).abs() < 1e-6, "platform at (N+1) h");
    assert!((z(4.0, 1.15) - h).abs() < 1e-6, "rings are square annuli");
    let zi = |u: f32, v: f32| tile_height(TerrainType::InvertedPyramidStairs, &p, l, d, &n, u, v);
    assert!((zi(1.45, 4.0) + 2.0 * h).abs() < 1e-6);
    assert!((zi(4.0, 4.0) + 7.0 * h).abs() < 1e-6);
    assert_eq!(zi(0.2, 0.2), 0.0);
}

#[test]
fn slope_heights_match_formula() {
    let p = SubTerrainParams::isaaclab_rough();
    let (l, d) = (8.0, 0.75);
    let s = 0.3;
    let n = TileNoise::default();
    let z = |u: f32, v: f32| tile_height(TerrainType::PyramidSlope, &p, l, d, &n, u, v);
    // along the centre line the surface rises with slope s from the slope border (0.25 m)
    let a = z(1.25, 4.0);
    let b = z(2.25, 4.0);
    assert!((a - s * 1.0).abs() < 1e-5, "{a}");
    assert!((b - a - s).abs() < 1e-5, "slope {}", b - a);
    // platform: h_max · f_pf², h_max = s · 3.75, f_pf = (3.75 - 1) / 3.75
    let fpf: f32 = 2.75 / 3.75;
    let top = s * 3.75 * fpf * fpf;
    assert!((z(4.0, 4.0) - top).abs() < 1e-5);
    assert!((z(4.5, 3.6) - top).abs() < 1e-5);
    assert_eq!(z(0.1, 4.0), 0.0);
    let zi = |u: f32, v: f32| tile_height(TerrainType::InvertedPyramidSlope, &p, l, d, &n, u, v);
    assert!((zi(4.0, 4.0) + top).abs() < 1e-5);
    assert!((zi(1.25, 4.0) + s).abs() < 1e-5);
}

#[test]
fn boxes_and_rough_within_range() {
    let p = SubTerrainParams::isaaclab_rough();
    let mut rng = StdRng::seed_from_u64(3);
    let d = 0.4;
    let g = 0.05 + 0.4 * 0.15;
    let nb = tile_noise(TerrainType::Boxes, &p, 8.0, d, &mut rng);
    assert_eq!(nb.n, 17);
    assert!(nb.values.iter().all(|v| v.abs() <= g + 1e-6));
    assert!(nb.values.iter().any(|v| *v < -0.5 * g) && nb.values.iter().any(|v| *v > 0.5 * g));
    let z = |u, v| tile_height(TerrainType::Boxes, &p, 8.0, d, &nb, u, v);
    assert!((z(4.0, 4.0) - g).abs() < 1e-6, "platform at grid height");
    assert_eq!(z(0.1, 3.0), 0.0, "border (0.175 m) flat");
    // cell (0, 0) spans [0.175, 0.625)
    assert_eq!(z(0.3, 0.3), nb.values[0]);
    let nr = tile_noise(TerrainType::RandomRough, &p, 8.0, d, &mut rng);
    let levels = [0.02f32, 0.04, 0.06, 0.08, 0.10];
    assert!(
        nr.values
            .iter()
            .all(|v| levels.iter().any(|l| (l - v).abs() < 1e-6)),
        "discrete noise levels"
    );
    for k in 0..200 {
        let u = 0.3 + 7.4 * (k as f32 / 200.0);
        let h = tile_height(TerrainType::RandomRough, &p, 8.0, d, &nr, u, 8.0 - u);
        assert!((0.02 - 1e-6..=0.10 + 1e-6).contains(&h), "{h}");
    }
}

#[test]
fn generated_grid_border_origins_and_scan() {
    let spec = small_spec(TerrainPreset::Curriculum);
    let t = Terrain::generate(&spec).unwrap();
    assert_eq!((t.nx, t.ny), (1681, 3281));
    // flat border
    assert_eq!(t.height_at(t.x0 + 0.5, 0.0), 0.0);
    assert_eq!(t.height_at(0.0, t.y0 + 1.0), 0.0);
    assert_eq!(t.height_at(1e6, 0.0), 0.0);
    // stairs tile (level 3, col 0): origin on the platform at (N+1) h
    let d = t.tile_difficulty(3, 0);
    assert!((0.3..0.4).contains(&d));
    let o = t.tile_origin(3, 0);
    let h = stairs_step_height(&spec.params, d);
    assert!((o[2] - 7.0 * h).abs() < 1e-5, "{} vs {}", o[2], 7.0 * h);
    assert!((t.height_at(o[0], o[1]) - o[2]).abs() < 1e-5);
    // the grid reproduces the closed form away from edges
    let (u, v) = (1.46, 4.02);
    let tile_x0 = o[0] - 4.0;
    let tile_y0 = o[1] - 4.0;
    assert!((t.height_at(tile_x0 + u, tile_y0 + v) - 2.0 * h).abs() < 1e-5);
    // inverted stairs origin at the bottom
    let oi = t.tile_origin(3, 4);
    assert_eq!(t.tile_type(4), TerrainType::InvertedPyramidStairs);
    let hi = stairs_step_height(&spec.params, t.tile_difficulty(3, 4));
    assert!((oi[2] + 7.0 * hi).abs() < 1e-5);
    // height scan: standing 0.6 m above the stairs platform, a flat patch reads 0.1 everywhere
    let mut scan = [0.0f32; 187];
    assert_eq!(t.sample_scan([o[0], o[1], o[2] + 0.6], 0.7, &mut scan), 187);
    assert!(scan.iter().all(|s| (s - 0.1).abs() < 1e-4), "{scan:?}");
}

#[test]
fn scan_order_and_yaw() {
    // a slope tile: height increases along +x near the tile's -x side
    let spec = small_spec(TerrainPreset::Curriculum);
    let t = Terrain::generate(&spec).unwrap();
    let col = 16;
    assert_eq!(t.tile_type(col), TerrainType::PyramidSlope);
    let o = t.tile_origin(5, col);
    let base = [o[0] - 2.0, o[1], 2.0];
    let mut a = [0.0f32; 187];
    t.sample_scan(base, 0.0, &mut a);
    // x fastest: a[0] is (-0.8, -0.5), a[16] is (0.8, -0.5); going forward (+x) is uphill
    assert!(a[16] < a[0], "{} {}", a[16], a[0]);
    for i in 0..187 {
        let (ix, iy) = (i % 17, i / 17);
        let (px, py) = (-0.8 + 0.1 * ix as f32, -0.5 + 0.1 * iy as f32);
        let want = 2.0 - t.height_at(base[0] + px, base[1] + py) - 0.5;
        assert!((a[i] - want).abs() < 1e-5);
    }
    // yaw = 90°: the scan's forward axis is world +y
    let mut b = [0.0f32; 187];
    t.sample_scan(base, std::f32::consts::FRAC_PI_2, &mut b);
    let want = 2.0 - t.height_at(base[0] + 0.5, base[1] + 0.8) - 0.5; // point (0.8, -0.5)
    assert!((b[16] - want).abs() < 1e-4);
}

#[test]
fn flat_preset_has_no_grid() {
    let spec = small_spec(TerrainPreset::Flat);
    let t = Terrain::generate(&spec).unwrap();
    assert!(t.is_flat());
    assert!(t.heights.is_empty());
    assert_eq!(t.height_at(3.0, -7.0), 0.0);
    assert_eq!(t.tile_origin(9, 19)[2], 0.0);
    assert!(!spec.curriculum);
}

#[test]
fn curriculum_promotes_demotes_and_redraws() {
    let spec = small_spec(TerrainPreset::Curriculum);
    let mut rng = StdRng::seed_from_u64(1);
    let mut c = Curriculum::new(40, &spec, &mut rng);
    assert!((0..40).all(|e| c.level(e) <= 5));
    assert_eq!(c.col(0), 0);
    assert_eq!(c.col(39), 19);
    assert_eq!(c.col(2), 1);
    c.set_level(0, 3);
    // walked 4.5 m > 4 m: promoted
    assert_eq!(c.update(0, 4.5, 1.0, 20.0, &mut rng), LevelChange::Promoted);
    assert_eq!(c.level(0), 4);
    // walked 3 m with |cmd| = 0.5: 3 < 0.5 * 20 * 0.5 = 5: demoted
    assert_eq!(c.update(0, 3.0, 0.5, 20.0, &mut rng), LevelChange::Demoted);
    assert_eq!(c.level(0), 3);
    // walked 3 m with |cmd| = 0.2: 3 >= 2: kept
    assert_eq!(c.update(0, 3.0, 0.2, 20.0, &mut rng), LevelChange::Kept);
    assert_eq!(c.level(0), 3);
    // exactly half a tile is not a promotion (strict >)
    assert_eq!(c.update(0, 4.0, 0.0, 20.0, &mut rng), LevelChange::Kept);
    // level 0 never goes negative
    c.set_level(1, 0);
    assert_eq!(c.update(1, 0.0, 1.0, 20.0, &mut rng), LevelChange::Kept);
    assert_eq!(c.level(1), 0);
    // solving the last level redraws uniformly in 0..10
    let mut seen = [false; 10];
    for _ in 0..400 {
        c.set_level(2, 9);
        assert_eq!(c.update(2, 6.0, 1.0, 20.0, &mut rng), LevelChange::Redrawn);
        seen[c.level(2)] = true;
    }
    assert!(seen.iter().all(|s| *s), "{seen:?}");
    // means
    for e in 0..40 {
        c.set_level(e, if e < 20 { 2 } else { 6 });
    }
    assert!((c.mean_level() - 4.0).abs() < 1e-6);
    let t = Terrain::generate(&TerrainSpec {
        border_width: 0.0,
        horizontal_resolution: 0.5,
        ..spec
    })
    .unwrap();
    let mut out = [(TerrainType::Flat, 0.0, 0); 7];
    let k = c.mean_level_by_type(&t, &mut out);
    assert_eq!(k, 6);
    assert_eq!(out[0], (TerrainType::PyramidStairs, 2.0, 8));
    assert_eq!(out[5], (TerrainType::InvertedPyramidSlope, 6.0, 4));
}

#[test]
fn disabled_curriculum_keeps_levels() {
    let spec = small_spec(TerrainPreset::SimpleRough);
    let mut rng = StdRng::seed_from_u64(1);
    let mut c = Curriculum::new(4, &spec, &mut rng);
    let l = c.level(0);
    assert_eq!(c.update(0, 100.0, 1.0, 20.0, &mut rng), LevelChange::Kept);
    assert_eq!(c.level(0), l);
}

#[test]
fn paper_preset_scales_rough_with_difficulty() {
    let p = SubTerrainParams::paper();
    assert_eq!(rough_levels(&p, 0.0).2, 1);
    let (lo, step, count) = rough_levels(&p, 0.95);
    assert!((lo + step * (count - 1) as f32) <= 0.30 + 1e-6);
    assert!(count >= 13);
    let q = SubTerrainParams::isaaclab_rough();
    assert_eq!(
        rough_levels(&q, 0.0).2,
        5,
        "IsaacLab ignores the difficulty"
    );
}

#[test]
fn terrain_type_names_are_the_serde_names_and_the_proportions_keys() {
    #[derive(serde::Deserialize)]
    struct One {
        t: TerrainType,
    }
    for (i, t) in TerrainType::ALL.into_iter().enumerate() {
        assert_eq!(t.index(), i);
        let parsed: One = toml::from_str(&format!("t = \"{}\"", t.as_str())).unwrap();
        assert_eq!(parsed.t, t);
        // Unnamed keys keep IsaacLab's shares, none of which is 1.
        let proportions: TypeProportions =
            toml::from_str(&format!("{} = 1.0", t.as_str())).unwrap();
        assert_eq!(
            proportions.as_array()[i],
            1.0,
            "{t} is the proportions key of its index"
        );
    }
    assert_eq!(TerrainType::from_name("stairs"), None);
    assert!(TerrainType::names().ends_with("pyramid_slope or inverted_pyramid_slope"));
}

/// `feet_clearance_radius`: the ground a swing foot is measured against is the highest within the
/// radius, so a foot 8 cm before a stair riser is asked to clear the step beyond it.
#[test]
fn max_height_within_sees_the_step_ahead() {
    let spec = small_spec(TerrainPreset::Curriculum);
    let t = Terrain::generate(&spec).unwrap();
    let o = t.tile_origin(3, 0);
    let h = stairs_step_height(&spec.params, t.tile_difficulty(3, 0));
    // On the first ring (height h) of a pyramid-stairs tile, 8 cm before the second (2 h).
    let (x, y) = (o[0] - 4.0 + 1.22, o[1]);
    assert!((t.height_at(x, y) - h).abs() < 1e-5);
    assert_eq!(t.max_height_within(x, y, 0.0), t.height_at(x, y));
    assert!(
        (t.max_height_within(x, y, 0.02) - h).abs() < 1e-5,
        "the riser is farther"
    );
    assert!(
        (t.max_height_within(x, y, 0.1) - 2.0 * h).abs() < 1e-5,
        "the step ahead"
    );
    // The highest, not the nearest: from the second ring the first (lower) one is ignored.
    let (x2, y2) = (o[0] - 4.0 + 1.38, o[1]);
    assert!((t.max_height_within(x2, y2, 0.1) - 2.0 * h).abs() < 1e-5);
    let flat = Terrain::generate(&small_spec(TerrainPreset::Flat)).unwrap();
    assert_eq!(flat.max_height_within(1.0, 2.0, 0.1), 0.0);
}
