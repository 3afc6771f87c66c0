//! Terrain: a height-grid generator for the IsaacLab 2.1 rough-terrain set, height queries for the
//! height scan, and the terrain-level curriculum. Pure `f32` math, no physics.
//!
//! # Public API
//! - [`TerrainSpec`] (resolved from [`crate::config::TerrainConfig`]): `num_rows` levels (along x) ×
//!   `num_cols` columns (along y) of square tiles, per-type [`SubTerrainParams`] and
//!   [`TypeProportions`], flat border, grid resolution, seed.
//! - [`Terrain::generate`]`(&spec) -> Result<Terrain, TerrainError>`: the height grid
//!   (`heights[iy * nx + ix]` is the height at `x = x0 + ix·res, y = y0 + iy·res`, x fastest), the
//!   per-tile difficulty, type and spawn origin. The tile area is centred on the world origin;
//!   level `l` is the tile row at `x ∈ [−rows·L/2 + l·L, … + L]`, column `c` at
//!   `y ∈ [−cols·L/2 + c·L, … + L]` (IsaacLab layout: rows = difficulty along x). The flat preset
//!   stores no grid (`nx = ny = 0`, [`Terrain::is_flat`]) and every height is 0.
//! - Queries: [`Terrain::height_at`] (bilinear on the grid = the surface a triangulated heightfield
//!   collider sees, up to the choice of diagonal; 0 outside the grid), [`Terrain::sample_scan`] (the
//!   17 × 11 yaw-aligned height scan in IsaacLab order and convention), [`Terrain::tile_origin`],
//!   [`Terrain::tile_type`], [`Terrain::tile_difficulty`].
//! - Per-type closed-form heights: [`tile_height`] (`type, difficulty, params, local x, y`) used by
//!   the generator and the tests; random types take a [`TileNoise`].
//! - [`Curriculum`]: each env's (level, column), the IsaacLab `terrain_levels_vel` rule
//!   ([`Curriculum::update`]), mean level and per-type mean level.
//!
//! Formulas follow IsaacLab 2.1 `terrains/trimesh/mesh_terrains.py` (stairs, boxes) and
//! `terrains/height_field/hf_terrains.py` (rough, slopes); deviations are listed in `TASK_NOTES.md`.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::config::ConfigError;

/// Errors of terrain generation.
#[derive(Debug, Error)]
pub enum TerrainError {
    /// The spec is invalid.
    #[error("invalid terrain spec: {0}")]
    Config(#[from] ConfigError),
    /// The grid would be too large.
    #[error(
        "terrain grid of {nx} x {ny} samples is too large (limit {limit})\nhint: raise horizontal_resolution or lower border_width / num_rows / num_cols"
    )]
    TooLarge { nx: usize, ny: usize, limit: usize },
}

/// Maximum number of grid samples (200 M f32 = 800 MB).
pub const MAX_GRID_SAMPLES: usize = 200_000_000;

/// The sub-terrain types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TerrainType {
    Flat,
    PyramidStairs,
    InvertedPyramidStairs,
    Boxes,
    RandomRough,
    PyramidSlope,
    InvertedPyramidSlope,
}

// `ALL` is in the order of [`TypeProportions`]; the names are the snake-case serde names (tested).
l3p_names::string_enum!(TerrainType {
    Flat => "flat",
    PyramidStairs => "pyramid_stairs",
    InvertedPyramidStairs => "inverted_pyramid_stairs",
    Boxes => "boxes",
    RandomRough => "random_rough",
    PyramidSlope => "pyramid_slope",
    InvertedPyramidSlope => "inverted_pyramid_slope",
});

impl TerrainType {
    /// Index into [`TerrainType::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Made of flat tops and vertical faces (stairs, boxes): IsaacLab builds these as meshes; here
    /// they collide as [`Terrain::stepped_mesh`] when the spec asks for vertical faces.
    pub fn is_stepped(self) -> bool {
        matches!(
            self,
            TerrainType::PyramidStairs | TerrainType::InvertedPyramidStairs | TerrainType::Boxes
        )
    }
}

/// Relative share of columns per type (normalised when used).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TypeProportions {
    pub flat: f32,
    pub pyramid_stairs: f32,
    pub inverted_pyramid_stairs: f32,
    pub boxes: f32,
    pub random_rough: f32,
    pub pyramid_slope: f32,
    pub inverted_pyramid_slope: f32,
}

impl Default for TypeProportions {
    fn default() -> Self {
        TypeProportions::isaaclab_rough()
    }
}

impl TypeProportions {
    /// All zero.
    pub fn zero() -> Self {
        TypeProportions {
            flat: 0.0,
            pyramid_stairs: 0.0,
            inverted_pyramid_stairs: 0.0,
            boxes: 0.0,
            random_rough: 0.0,
            pyramid_slope: 0.0,
            inverted_pyramid_slope: 0.0,
        }
    }

    /// IsaacLab `ROUGH_TERRAINS_CFG`: 0.2, 0.2, 0.2, 0.2, 0.1, 0.1.
    pub fn isaaclab_rough() -> Self {
        TypeProportions {
            flat: 0.0,
            pyramid_stairs: 0.2,
            inverted_pyramid_stairs: 0.2,
            boxes: 0.2,
            random_rough: 0.2,
            pyramid_slope: 0.1,
            inverted_pyramid_slope: 0.1,
        }
    }

    /// Only one type.
    pub fn only(t: TerrainType) -> Self {
        let mut p = TypeProportions::zero();
        *p.as_array_mut()[t.index()] = 1.0;
        p
    }

    /// Values in [`TerrainType::ALL`] order.
    pub fn as_array(&self) -> [f32; 7] {
        [
            self.flat,
            self.pyramid_stairs,
            self.inverted_pyramid_stairs,
            self.boxes,
            self.random_rough,
            self.pyramid_slope,
            self.inverted_pyramid_slope,
        ]
    }

    fn as_array_mut(&mut self) -> [&mut f32; 7] {
        [
            &mut self.flat,
            &mut self.pyramid_stairs,
            &mut self.inverted_pyramid_stairs,
            &mut self.boxes,
            &mut self.random_rough,
            &mut self.pyramid_slope,
            &mut self.inverted_pyramid_slope,
        ]
    }

    /// Type of column `col` of `num_cols` (IsaacLab `_generate_curriculum_terrains`: the first type
    /// whose normalised cumulative proportion exceeds `col / num_cols + 0.001`).
    pub fn column_type(&self, col: usize, num_cols: usize) -> TerrainType {
        let p = self.as_array();
        let total: f32 = p.iter().sum();
        let x = col as f32 / num_cols.max(1) as f32 + 0.001;
        let mut cum = 0.0;
        let mut last = TerrainType::Flat;
        for (i, v) in p.iter().enumerate() {
            if *v <= 0.0 {
                continue;
            }
            cum += v / total;
            last = TerrainType::ALL[i];
            if x < cum {
                return last;
            }
        }
        last
    }
}

/// Per-type parameters (IsaacLab names; lengths in metres). Ranges are mapped linearly by the
/// tile's difficulty `d ∈ [0, 1)`: `lo + d·(hi − lo)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SubTerrainParams {
    pub stairs_step_height: [f32; 2],
    pub stairs_step_width: f32,
    pub stairs_platform_width: f32,
    pub stairs_border_width: f32,
    pub boxes_height: [f32; 2],
    pub boxes_grid_width: f32,
    pub boxes_platform_width: f32,
    pub rough_noise: [f32; 2],
    pub rough_noise_step: f32,
    /// Spacing of the random-height lattice (IsaacLab `downsampled_scale`, default = its 0.1 m
    /// horizontal scale).
    pub rough_downsampled_scale: f32,
    pub rough_border_width: f32,
    /// IsaacLab ignores the difficulty for random rough ground; when true the upper bound of the
    /// noise grows with it instead (`lo + d·(hi − lo)`), used by the `paper` preset.
    pub rough_scales_with_difficulty: bool,
    pub slope: [f32; 2],
    pub slope_platform_width: f32,
    pub slope_border_width: f32,
}

impl SubTerrainParams {
    /// IsaacLab 2.1 `ROUGH_TERRAINS_CFG`.
    pub fn isaaclab_rough() -> Self {
        SubTerrainParams {
            stairs_step_height: [0.05, 0.23],
            stairs_step_width: 0.3,
            stairs_platform_width: 3.0,
            stairs_border_width: 1.0,
            boxes_height: [0.05, 0.2],
            boxes_grid_width: 0.45,
            boxes_platform_width: 2.0,
            rough_noise: [0.02, 0.10],
            rough_noise_step: 0.02,
            rough_downsampled_scale: 0.1,
            rough_border_width: 0.25,
            rough_scales_with_difficulty: false,
            slope: [0.0, 0.4],
            slope_platform_width: 2.0,
            slope_border_width: 0.25,
        }
    }

    /// The L3P paper's terrain table (same geometry, larger upper bounds).
    pub fn paper() -> Self {
        SubTerrainParams {
            stairs_step_height: [0.05, 0.8],
            boxes_height: [0.05, 0.8],
            rough_noise: [0.02, 0.30],
            rough_noise_step: 0.02,
            rough_scales_with_difficulty: true,
            slope: [0.0, 0.8],
            ..SubTerrainParams::isaaclab_rough()
        }
    }
}

impl Default for SubTerrainParams {
    fn default() -> Self {
        SubTerrainParams::isaaclab_rough()
    }
}

/// Resolved terrain generator input (see [`crate::config::TerrainConfig::resolve`]).
#[derive(Debug, Clone, PartialEq)]
pub struct TerrainSpec {
    pub num_rows: usize,
    pub num_cols: usize,
    pub tile_size: f32,
    pub horizontal_resolution: f32,
    pub border_width: f32,
    pub max_init_level: usize,
    /// Every env starts at this level (see `TerrainConfig::init_level`).
    pub init_level: Option<usize>,
    pub seed: u64,
    /// Whether the terrain-level curriculum moves envs between levels.
    pub curriculum: bool,
    pub proportions: TypeProportions,
    pub params: SubTerrainParams,
    /// Build the heightfield with parry's `FIX_INTERNAL_EDGES` (see `TerrainConfig`).
    pub fix_internal_edges: bool,
    /// Stepped tiles (stairs, boxes) as treads and vertical risers (see `TerrainConfig`).
    pub vertical_faces: bool,
}

fn bad(key: &str, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        key: format!("terrain.{key}"),
        reason: reason.into(),
    }
}

impl TerrainSpec {
    /// Checks ranges; errors name the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.num_rows == 0 || self.num_rows > 1000 {
            return Err(bad(
                "num_rows",
                format!("expected 1..=1000, got {}", self.num_rows),
            ));
        }
        if self.num_cols == 0 || self.num_cols > 1000 {
            return Err(bad(
                "num_cols",
                format!("expected 1..=1000, got {}", self.num_cols),
            ));
        }
        if !(self.tile_size.is_finite() && self.tile_size >= 1.0) {
            return Err(bad(
                "tile_size",
                format!("expected a finite size >= 1 m, got {}", self.tile_size),
            ));
        }
        let r = self.horizontal_resolution;
        if !(r.is_finite() && r > 0.0 && r <= self.tile_size / 8.0) {
            return Err(bad(
                "horizontal_resolution",
                format!(
                    "expected 0 < resolution <= tile_size / 8, got {r}\nhint: 0.05 keeps stair risers sharp, 0.1 is IsaacLab's"
                ),
            ));
        }
        if !(self.border_width.is_finite() && self.border_width >= 0.0) {
            return Err(bad(
                "border_width",
                format!("expected a finite width >= 0, got {}", self.border_width),
            ));
        }
        if let Some(level) = self.init_level
            && level >= self.num_rows
        {
            return Err(bad(
                "init_level",
                format!("expected < num_rows ({}), got {level}", self.num_rows),
            ));
        }
        if self.max_init_level >= self.num_rows {
            return Err(bad(
                "max_init_level",
                format!(
                    "expected < num_rows ({}), got {}",
                    self.num_rows, self.max_init_level
                ),
            ));
        }
        let p = self.proportions.as_array();
        if p.iter().any(|v| !v.is_finite() || *v < 0.0) || p.iter().sum::<f32>() <= 0.0 {
            return Err(bad(
                "proportions",
                "expected finite non-negative shares with a positive sum",
            ));
        }
        let q = &self.params;
        for (k, v) in [
            ("stairs_step_height", q.stairs_step_height),
            ("boxes_height", q.boxes_height),
            ("rough_noise", q.rough_noise),
            ("slope", q.slope),
        ] {
            if !(v[0].is_finite() && v[1].is_finite() && v[0] <= v[1] && v[0] >= 0.0) {
                return Err(bad(
                    k,
                    format!("expected finite 0 <= lo <= hi, got [{}, {}]", v[0], v[1]),
                ));
            }
        }
        for (k, v) in [
            ("stairs_step_width", q.stairs_step_width),
            ("boxes_grid_width", q.boxes_grid_width),
            ("rough_noise_step", q.rough_noise_step),
            ("rough_downsampled_scale", q.rough_downsampled_scale),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(k, format!("expected a finite value > 0, got {v}")));
            }
        }
        let l = self.tile_size;
        for (k, v) in [
            ("stairs_platform_width", q.stairs_platform_width),
            ("stairs_border_width", q.stairs_border_width),
            ("boxes_platform_width", q.boxes_platform_width),
            ("rough_border_width", q.rough_border_width),
            ("slope_platform_width", q.slope_platform_width),
            ("slope_border_width", q.slope_border_width),
        ] {
            if !(v.is_finite() && v >= 0.0 && v < l / 2.0) {
                return Err(bad(
                    k,
                    format!("expected 0 <= value < tile_size / 2, got {v}"),
                ));
            }
        }
        if l - 2.0 * q.stairs_border_width < q.stairs_platform_width {
            return Err(bad(
                "stairs_platform_width",
                "platform does not fit inside the stairs border",
            ));
        }
        if q.boxes_grid_width >= l {
            return Err(bad(
                "boxes_grid_width",
                "a cell must be smaller than the tile",
            ));
        }
        Ok(())
    }
}

/// Random content of one tile: the per-cell heights of boxes or the rough-noise lattice.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TileNoise {
    /// Lattice side (cells or lattice points per axis).
    pub n: usize,
    /// `values[j * n + i]`, `i` along x.
    pub values: Vec<f32>,
}

/// Number of stairs rings (IsaacLab: `(size − 2·border − platform) // (2·step_width) + 1`).
pub fn stairs_num_steps(p: &SubTerrainParams, tile_size: f32) -> usize {
    let x = (tile_size - 2.0 * p.stairs_border_width - p.stairs_platform_width) as f64
        / (2.0 * p.stairs_step_width) as f64;
    (x + 1e-6).floor().max(0.0) as usize + 1
}

fn lerp(r: [f32; 2], d: f32) -> f32 {
    r[0] + d * (r[1] - r[0])
}

/// Step height of (inverted) pyramid stairs at difficulty `d`.
pub fn stairs_step_height(p: &SubTerrainParams, d: f32) -> f32 {
    lerp(p.stairs_step_height, d)
}

/// Boxes grid height at difficulty `d`.
pub fn boxes_height(p: &SubTerrainParams, d: f32) -> f32 {
    lerp(p.boxes_height, d)
}

/// Slope (rise over run) at difficulty `d` (positive; the inverted type uses its negative).
pub fn slope_at(p: &SubTerrainParams, d: f32) -> f32 {
    lerp(p.slope, d)
}

/// The discrete values the rough noise is drawn from at difficulty `d`
/// (IsaacLab `arange(min, max + step, step)`): `(lo, step, count)`.
pub fn rough_levels(p: &SubTerrainParams, d: f32) -> (f32, f32, usize) {
    let lo = p.rough_noise[0];
    let hi = if p.rough_scales_with_difficulty {
        lerp(p.rough_noise, d)
    } else {
        p.rough_noise[1]
    };
    let count = (((hi - lo) / p.rough_noise_step) as f64 + 1e-6)
        .floor()
        .max(0.0) as usize
        + 1;
    (lo, p.rough_noise_step, count)
}

/// Number of box cells per axis and the border left around them (IsaacLab `random_grid_terrain`).
pub fn boxes_layout(p: &SubTerrainParams, tile_size: f32) -> (usize, f32) {
    let n = ((tile_size / p.boxes_grid_width) as f64 + 1e-6).floor() as usize;
    let border = tile_size - n as f32 * p.boxes_grid_width;
    (n, border)
}

/// Number of rough lattice points per axis inside the rough border.
pub fn rough_lattice_points(p: &SubTerrainParams, tile_size: f32) -> usize {
    let inner = tile_size - 2.0 * p.rough_border_width;
    ((inner / p.rough_downsampled_scale) as f64 + 1e-6).floor() as usize + 1
}

/// Draws the random content of a tile of type `t` at difficulty `d`.
pub fn tile_noise<R: Rng + ?Sized>(
    t: TerrainType,
    p: &SubTerrainParams,
    tile_size: f32,
    d: f32,
    rng: &mut R,
) -> TileNoise {
    match t {
        TerrainType::Boxes => {
            let (n, _) = boxes_layout(p, tile_size);
            let g = boxes_height(p, d);
            let values = (0..n * n)
                .map(|_| {
                    if g > 0.0 {
                        rng.random_range(-g..=g)
                    } else {
                        0.0
                    }
                })
                .collect();
            TileNoise { n, values }
        }
        TerrainType::RandomRough => {
            let n = rough_lattice_points(p, tile_size);
            let (lo, step, count) = rough_levels(p, d);
            let values = (0..n * n)
                .map(|_| lo + step * rng.random_range(0..count) as f32)
                .collect();
            TileNoise { n, values }
        }
        _ => TileNoise::default(),
    }
}

/// Height of a tile of type `t` at difficulty `d` at local coordinates `(u, v) ∈ [0, L]²` measured
/// from the tile's lower corner, on half-open cells (the generator takes the max over an ε
/// neighbourhood so that sample points on an edge get the top of the higher side).
///
/// - stairs: ring `k` (Chebyshev inset `k·w ≤ δ < (k+1)·w` from the stairs border) at `(k+1)·h`,
///   the centre at `(N+1)·h`, the border at 0; inverted: negated.
/// - boxes: cell value in `[−g, g]`, the central platform at `g`, the border at 0.
/// - rough: bilinear interpolation of the lattice inside the rough border, 0 outside.
/// - slopes: `h_max · f_x · f_y` with `f = 1 − |u − L/2| / (L_in/2)` inside the slope border,
///   `h_max = s·L_in/2`, clipped to the platform height `h_max·f_pf²` (IsaacLab `pyramid_sloped_terrain`).
pub fn tile_height(
    t: TerrainType,
    p: &SubTerrainParams,
    tile_size: f32,
    d: f32,
    noise: &TileNoise,
    u: f32,
    v: f32,
) -> f32 {
    let l = tile_size;
    if !(0.0..=l).contains(&u) || !(0.0..=l).contains(&v) {
        return 0.0;
    }
    match t {
        TerrainType::Flat => 0.0,
        TerrainType::PyramidStairs | TerrainType::InvertedPyramidStairs => {
            let b = p.stairs_border_width;
            let inset = (u - b).min(l - b - u).min(v - b).min(l - b - v);
            if inset < 0.0 {
                return 0.0;
            }
            let h = stairs_step_height(p, d);
            let n = stairs_num_steps(p, l);
            let k = (inset / p.stairs_step_width).floor() as usize;
            let z = if k < n {
                (k + 1) as f32 * h
            } else {
                (n + 1) as f32 * h
            };
            if t == TerrainType::PyramidStairs {
                z
            } else {
                -z
            }
        }
        TerrainType::Boxes => {
            let g = boxes_height(p, d);
            let half_pf = 0.5 * p.boxes_platform_width;
            if (u - 0.5 * l).abs() <= half_pf && (v - 0.5 * l).abs() <= half_pf {
                return g;
            }
            let (n, border) = boxes_layout(p, l);
            let off = 0.5 * border;
            let (fu, fv) = (
                (u - off) / p.boxes_grid_width,
                (v - off) / p.boxes_grid_width,
            );
            if fu < 0.0 || fv < 0.0 {
                return 0.0;
            }
            let (i, j) = (fu.floor() as usize, fv.floor() as usize);
            if i >= n || j >= n || noise.n != n {
                return 0.0;
            }
            noise.values[j * n + i]
        }
        TerrainType::RandomRough => {
            let b = p.rough_border_width;
            let s = p.rough_downsampled_scale;
            let n = noise.n;
            if n < 2 {
                return 0.0;
            }
            let extent = (n - 1) as f32 * s;
            let (x, y) = (u - b, v - b);
            if x < 0.0 || y < 0.0 || x > extent || y > extent {
                return 0.0;
            }
            let (fx, fy) = (x / s, y / s);
            let i = (fx.floor() as usize).min(n - 2);
            let j = (fy.floor() as usize).min(n - 2);
            let (tx, ty) = (fx - i as f32, fy - j as f32);
            let at = |i: usize, j: usize| noise.values[j * n + i];
            let a = at(i, j) * (1.0 - tx) + at(i + 1, j) * tx;
            let c = at(i, j + 1) * (1.0 - tx) + at(i + 1, j + 1) * tx;
            a * (1.0 - ty) + c * ty
        }
        TerrainType::PyramidSlope | TerrainType::InvertedPyramidSlope => {
            let b = p.slope_border_width;
            let half = 0.5 * (l - 2.0 * b);
            let fx = 1.0 - (u - 0.5 * l).abs() / half;
            let fy = 1.0 - (v - 0.5 * l).abs() / half;
            if fx < 0.0 || fy < 0.0 {
                return 0.0;
            }
            let s = slope_at(p, d);
            let s = if t == TerrainType::PyramidSlope {
                s
            } else {
                -s
            };
            let hmax = s * half;
            let fpf = ((half - 0.5 * p.slope_platform_width) / half).max(0.0);
            let zpf = hmax * fpf * fpf;
            (hmax * fx * fy).clamp(zpf.min(0.0), zpf.max(0.0))
        }
    }
}

/// The generated terrain.
#[derive(Debug, Clone)]
pub struct Terrain {
    pub spec: TerrainSpec,
    /// Samples along x (0 for the flat preset).
    pub nx: usize,
    /// Samples along y (0 for the flat preset).
    pub ny: usize,
    /// Grid spacing (m).
    pub resolution: f32,
    /// World x of sample column 0.
    pub x0: f32,
    /// World y of sample row 0.
    pub y0: f32,
    /// `heights[iy * nx + ix]` (m).
    pub heights: Vec<f32>,
    col_types: Vec<TerrainType>,
    difficulty: Vec<f32>,
    origins: Vec<[f32; 3]>,
}

/// Number of height-scan points along x (forward).
pub const SCAN_NX: usize = 17;
/// Number of height-scan points along y (left).
pub const SCAN_NY: usize = 11;
/// Height-scan spacing (m).
pub const SCAN_RES: f32 = 0.1;
/// IsaacLab `height_scan` offset: obs = base_z − hit_z − 0.5.
pub const SCAN_OFFSET: f32 = 0.5;

impl Terrain {
    /// Generates the terrain of `spec` (deterministic in `spec.seed`).
    pub fn generate(spec: &TerrainSpec) -> Result<Terrain, TerrainError> {
        spec.validate()?;
        let l = spec.tile_size;
        let (rows, cols) = (spec.num_rows, spec.num_cols);
        let col_types: Vec<TerrainType> = (0..cols)
            .map(|c| spec.proportions.column_type(c, cols))
            .collect();
        let mut rng = StdRng::seed_from_u64(spec.seed);
        // IsaacLab curriculum: difficulty = (row + U(0, 1)) / num_rows.
        let mut difficulty = vec![0.0f32; rows * cols];
        for r in 0..rows {
            for c in 0..cols {
                let u: f32 = rng.random();
                difficulty[r * cols + c] = ((r as f32 + u) / rows as f32).min(0.999_999);
            }
        }
        let all_flat = col_types.iter().all(|t| *t == TerrainType::Flat);
        let res = spec.horizontal_resolution;
        let width_x = rows as f32 * l + 2.0 * spec.border_width;
        let width_y = cols as f32 * l + 2.0 * spec.border_width;
        let x0 = -0.5 * width_x;
        let y0 = -0.5 * width_y;
        let (nx, ny) = if all_flat {
            (0, 0)
        } else {
            (
                ((width_x / res).round() as usize) + 1,
                ((width_y / res).round() as usize) + 1,
            )
        };
        if nx.saturating_mul(ny) > MAX_GRID_SAMPLES {
            return Err(TerrainError::TooLarge {
                nx,
                ny,
                limit: MAX_GRID_SAMPLES,
            });
        }
        let mut heights = vec![0.0f32; nx * ny];
        let mut origins = vec![[0.0f32; 3]; rows * cols];
        let eps = 1e-4 * res;
        for r in 0..rows {
            for c in 0..cols {
                let t = col_types[c];
                let d = difficulty[r * cols + c];
                let noise = tile_noise(t, &spec.params, l, d, &mut rng);
                let tx0 = -0.5 * rows as f32 * l + r as f32 * l;
                let ty0 = -0.5 * cols as f32 * l + c as f32 * l;
                origins[r * cols + c] = [tx0 + 0.5 * l, ty0 + 0.5 * l, 0.0];
                if nx == 0 || t == TerrainType::Flat {
                    continue;
                }
                let SampleRect {
                    ix_lo,
                    ix_hi,
                    iy_lo,
                    iy_hi,
                } = sample_rect([tx0, ty0], l, [x0, y0], res, [nx, ny]);
                let mut centre_max = f32::NEG_INFINITY;
                for iy in iy_lo..=iy_hi {
                    let v = y0 + iy as f32 * res - ty0;
                    for ix in ix_lo..=ix_hi {
                        let u = x0 + ix as f32 * res - tx0;
                        let mut h = f32::NEG_INFINITY;
                        for (du, dv) in [(-eps, -eps), (eps, -eps), (-eps, eps), (eps, eps)] {
                            h = h.max(tile_height(t, &spec.params, l, d, &noise, u + du, v + dv));
                        }
                        heights[iy * nx + ix] = h;
                        if (u - 0.5 * l).abs() <= 1.0 && (v - 0.5 * l).abs() <= 1.0 {
                            centre_max = centre_max.max(h);
                        }
                    }
                }
                // Spawn height: max over the central 2 m x 2 m (IsaacLab height-field origin rule;
                // equals the mesh terrains' analytic origins).
                if centre_max.is_finite() {
                    origins[r * cols + c][2] = centre_max;
                }
            }
        }
        Ok(Terrain {
            spec: spec.clone(),
            nx,
            ny,
            resolution: res,
            x0,
            y0,
            heights,
            col_types,
            difficulty,
            origins,
        })
    }

    /// True when there is no height grid (every height is 0).
    pub fn is_flat(&self) -> bool {
        self.nx == 0 || self.ny == 0
    }

    /// Number of levels (rows).
    pub fn num_levels(&self) -> usize {
        self.spec.num_rows
    }

    /// Number of columns.
    pub fn num_cols(&self) -> usize {
        self.spec.num_cols
    }

    /// Type of column `col` (clamped to the last column).
    pub fn tile_type(&self, col: usize) -> TerrainType {
        self.col_types[col.min(self.col_types.len() - 1)]
    }

    /// Difficulty in `[0, 1)` of tile (`level`, `col`) (clamped).
    pub fn tile_difficulty(&self, level: usize, col: usize) -> f32 {
        let (r, c) = self.clamp_tile(level, col);
        self.difficulty[r * self.spec.num_cols + c]
    }

    /// Spawn origin (centre x, y; ground height z) of tile (`level`, `col`) (clamped).
    pub fn tile_origin(&self, level: usize, col: usize) -> [f32; 3] {
        let (r, c) = self.clamp_tile(level, col);
        self.origins[r * self.spec.num_cols + c]
    }

    fn clamp_tile(&self, level: usize, col: usize) -> (usize, usize) {
        (
            level.min(self.spec.num_rows - 1),
            col.min(self.spec.num_cols - 1),
        )
    }

    /// Grid sample (clamped to the grid). Panics never; returns 0 on a flat terrain.
    #[inline]
    pub fn sample(&self, ix: usize, iy: usize) -> f32 {
        if self.is_flat() {
            return 0.0;
        }
        self.heights[iy.min(self.ny - 1) * self.nx + ix.min(self.nx - 1)]
    }

    /// Terrain height at world `(x, y)`: bilinear interpolation of the grid (on a stepped tile with
    /// vertical faces, the nearest sample: the mesh's step); 0 outside the grid (the flat border
    /// continues) and for non-finite input.
    #[inline]
    pub fn height_at(&self, x: f32, y: f32) -> f32 {
        if self.is_flat() {
            return 0.0;
        }
        let fx = (x - self.x0) / self.resolution;
        let fy = (y - self.y0) / self.resolution;
        // Also false for NaN.
        if !(fx >= 0.0 && fy >= 0.0 && fx <= (self.nx - 1) as f32 && fy <= (self.ny - 1) as f32) {
            return 0.0;
        }
        if self.stepped_at(x, y) {
            // The step of the nearest sample: what `stepped_mesh` builds.
            let i = ((fx + 0.5) as usize).min(self.nx - 1);
            let j = ((fy + 0.5) as usize).min(self.ny - 1);
            return self.heights[j * self.nx + i];
        }
        let i = (fx as usize).min(self.nx - 2);
        let j = (fy as usize).min(self.ny - 2);
        let (tx, ty) = (fx - i as f32, fy - j as f32);
        let row0 = j * self.nx + i;
        let row1 = row0 + self.nx;
        let a = self.heights[row0] * (1.0 - tx) + self.heights[row0 + 1] * tx;
        let b = self.heights[row1] * (1.0 - tx) + self.heights[row1 + 1] * tx;
        a * (1.0 - ty) + b * ty
    }

    /// The highest ground within `radius` (m) of `(x, y)`: [`Terrain::height_at`] at the point
    /// and on two rings around it (8 samples at `radius` / 2 and 16 at `radius`), so a step edge
    /// within the radius is seen whatever the direction. `radius <= 0`: the height at the point.
    pub fn max_height_within(&self, x: f32, y: f32, radius: f32) -> f32 {
        let mut highest = self.height_at(x, y);
        if self.is_flat() || radius <= 0.0 {
            return highest;
        }
        for (ring_radius, samples) in [(0.5 * radius, 8), (radius, 16)] {
            for k in 0..samples {
                let angle = std::f32::consts::TAU * k as f32 / samples as f32;
                let (sin, cos) = angle.sin_cos();
                highest = highest.max(self.height_at(x + ring_radius * cos, y + ring_radius * sin));
            }
        }
        highest
    }

    /// The tile (`level`, `col`) that holds world `(x, y)`, if any (the border holds none).
    pub fn tile_at(&self, x: f32, y: f32) -> Option<(usize, usize)> {
        let l = self.spec.tile_size;
        let fr = (x + 0.5 * self.spec.num_rows as f32 * l) / l;
        let fc = (y + 0.5 * self.spec.num_cols as f32 * l) / l;
        // Also false for NaN.
        if !(fr >= 0.0 && fc >= 0.0) {
            return None;
        }
        let (r, c) = (fr as usize, fc as usize);
        (r < self.spec.num_rows && c < self.spec.num_cols).then_some((r, c))
    }

    /// Whether world `(x, y)` lies on a stepped tile built with vertical faces.
    pub fn stepped_at(&self, x: f32, y: f32) -> bool {
        self.spec.vertical_faces
            && self
                .tile_at(x, y)
                .is_some_and(|(_, c)| self.col_types[c].is_stepped())
    }

    /// The grid samples of every stepped tile, when the spec asks for vertical faces (else none).
    pub fn stepped_tiles(&self) -> Vec<SampleRect> {
        if !self.spec.vertical_faces || self.is_flat() {
            return Vec::new();
        }
        let l = self.spec.tile_size;
        let mut out = Vec::new();
        for r in 0..self.spec.num_rows {
            for c in 0..self.spec.num_cols {
                if self.col_types[c].is_stepped() {
                    let tx0 = -0.5 * self.spec.num_rows as f32 * l + r as f32 * l;
                    let ty0 = -0.5 * self.spec.num_cols as f32 * l + c as f32 * l;
                    out.push(sample_rect(
                        [tx0, ty0],
                        l,
                        [self.x0, self.y0],
                        self.resolution,
                        [self.nx, self.ny],
                    ));
                }
            }
        }
        out
    }

    /// The mesh of the samples in `rect` as steps: each sample owns the square of the grid's
    /// spacing around it (clipped to the rect) as a flat top at its height, and a vertical face
    /// joins two neighbouring samples of different heights. Equal tops are merged into rectangles
    /// and faces into strips, so a stairs tile is a few hundred triangles. World coordinates
    /// (z up); triangles wind counter-clockwise seen from outside.
    pub fn stepped_mesh(&self, rect: &SampleRect) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let SampleRect {
            ix_lo,
            ix_hi,
            iy_lo,
            iy_hi,
        } = *rect;
        let res = self.resolution;
        // Cell edges: sample k's cell is [edge(k), edge(k + 1)], clipped to the rect.
        let edge = |k: usize, lo: usize, hi: usize, origin: f32| -> f32 {
            let k = k.clamp(lo, hi + 1);
            if k == lo {
                origin + lo as f32 * res
            } else if k == hi + 1 {
                origin + hi as f32 * res
            } else {
                origin + (k as f32 - 0.5) * res
            }
        };
        let ex = |k: usize| edge(k, ix_lo, ix_hi, self.x0);
        let ey = |k: usize| edge(k, iy_lo, iy_hi, self.y0);
        let h = |ix: usize, iy: usize| self.heights[iy * self.nx + ix];
        let mut mesh = MeshBuilder::default();

        // Tops: runs of equal height along x, merged with the same run of the next row.
        let mut open: Vec<[usize; 4]> = Vec::new(); // [ix0, ix1, iy0, iy1] (inclusive)
        let mut tops: Vec<[usize; 4]> = Vec::new();
        for iy in iy_lo..=iy_hi {
            let mut next = Vec::new();
            let mut ix0 = ix_lo;
            for ix in ix_lo..=ix_hi {
                if ix == ix_hi || h(ix + 1, iy) != h(ix0, iy) {
                    let run = [ix0, ix];
                    let key = h(ix0, iy).to_bits();
                    match open.iter().position(|o| {
                        o[..2] == run && o[3] + 1 == iy && h(o[0], o[2]).to_bits() == key
                    }) {
                        Some(k) => {
                            let mut o = open.swap_remove(k);
                            o[3] = iy;
                            next.push(o);
                        }
                        None => next.push([ix0, ix, iy, iy]),
                    }
                    ix0 = ix + 1;
                }
            }
            tops.append(&mut open);
            open = next;
        }
        tops.append(&mut open);
        for [ix0, ix1, iy0, iy1] in tops {
            let z = h(ix0, iy0);
            let (x0, x1, y0, y1) = (ex(ix0), ex(ix1 + 1), ey(iy0), ey(iy1 + 1));
            mesh.quad([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]);
        }

        // Faces between x-neighbours (at x = ex(ix + 1)), merged along y while the same.
        let mut faces: Vec<(usize, usize, usize, u32, u32)> = Vec::new(); // (ix, iy0, iy1, lo, hi)
        for iy in iy_lo..=iy_hi {
            for ix in ix_lo..ix_hi {
                let (a, b) = (h(ix, iy), h(ix + 1, iy));
                if a != b {
                    let key = (ix, a.to_bits(), b.to_bits());
                    match faces
                        .iter_mut()
                        .rev()
                        .find(|f| (f.0, f.3, f.4) == key && f.2 + 1 == iy)
                    {
                        Some(f) => f.2 = iy,
                        None => faces.push((ix, iy, iy, key.1, key.2)),
                    }
                }
            }
        }
        for (ix, iy0, iy1, a, b) in faces {
            let (a, b) = (f32::from_bits(a), f32::from_bits(b));
            let (x, y0, y1) = (ex(ix + 1), ey(iy0), ey(iy1 + 1));
            let (lo, hi) = (a.min(b), a.max(b));
            // Facing the lower side: −x when the left sample is the lower one.
            if a < b {
                mesh.quad([[x, y1, lo], [x, y0, lo], [x, y0, hi], [x, y1, hi]]);
            } else {
                mesh.quad([[x, y0, lo], [x, y1, lo], [x, y1, hi], [x, y0, hi]]);
            }
        }
        // Faces between y-neighbours (at y = ey(iy + 1)), merged along x while the same.
        let mut faces: Vec<(usize, usize, usize, u32, u32)> = Vec::new(); // (iy, ix0, ix1, lo, hi)
        for iy in iy_lo..iy_hi {
            for ix in ix_lo..=ix_hi {
                let (a, b) = (h(ix, iy), h(ix, iy + 1));
                if a != b {
                    let key = (iy, a.to_bits(), b.to_bits());
                    match faces.last_mut() {
                        Some(f) if (f.0, f.3, f.4) == key && f.2 + 1 == ix => f.2 = ix,
                        _ => faces.push((iy, ix, ix, key.1, key.2)),
                    }
                }
            }
        }
        for (iy, ix0, ix1, a, b) in faces {
            let (a, b) = (f32::from_bits(a), f32::from_bits(b));
            let (y, x0, x1) = (ey(iy + 1), ex(ix0), ex(ix1 + 1));
            let (lo, hi) = (a.min(b), a.max(b));
            if a < b {
                mesh.quad([[x0, y, lo], [x1, y, lo], [x1, y, hi], [x0, y, hi]]);
            } else {
                mesh.quad([[x1, y, lo], [x0, y, lo], [x0, y, hi], [x1, y, hi]]);
            }
        }
        (mesh.vertices, mesh.triangles)
    }

    /// Height scan around a base at `pos` (world) with yaw `yaw`, written into `out[..187]` in
    /// IsaacLab order (x fastest: `out[iy * 17 + ix]` is the point `(−0.8 + 0.1·ix, −0.5 + 0.1·iy)`
    /// in the yaw-aligned base frame) and convention: `base_z − height − 0.5`, NOT clipped (the
    /// observation builder adds noise, then clips to ±1).
    ///
    /// Returns the number of values written (187), or 0 when `out` is shorter.
    pub fn sample_scan(&self, pos: [f32; 3], yaw: f32, out: &mut [f32]) -> usize {
        let n = SCAN_NX * SCAN_NY;
        if out.len() < n {
            return 0;
        }
        let (s, c) = yaw.sin_cos();
        for iy in 0..SCAN_NY {
            let py = -0.5 * (SCAN_NY - 1) as f32 * SCAN_RES + iy as f32 * SCAN_RES;
            for ix in 0..SCAN_NX {
                let px = -0.5 * (SCAN_NX - 1) as f32 * SCAN_RES + ix as f32 * SCAN_RES;
                let wx = pos[0] + c * px - s * py;
                let wy = pos[1] + s * px + c * py;
                out[iy * SCAN_NX + ix] = pos[2] - self.height_at(wx, wy) - SCAN_OFFSET;
            }
        }
        n
    }

    /// Min and max of the grid (0, 0 when flat).
    pub fn height_range(&self) -> (f32, f32) {
        if self.is_flat() {
            return (0.0, 0.0);
        }
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for h in &self.heights {
            lo = lo.min(*h);
            hi = hi.max(*h);
        }
        (lo, hi)
    }
}

// ---------------------------------------------------------------------------------------------
// Curriculum

/// What [`Curriculum::update`] did to an env.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LevelChange {
    Promoted,
    Demoted,
    Kept,
    /// Solved the last level and was sent to a random level.
    Redrawn,
}

/// Each env's terrain level (row) and column, and the IsaacLab `terrain_levels_vel` rule.
#[derive(Debug, Clone)]
pub struct Curriculum {
    levels: Vec<usize>,
    cols: Vec<usize>,
    num_rows: usize,
    num_cols: usize,
    tile_size: f32,
    enabled: bool,
}

impl Curriculum {
    /// IsaacLab `_compute_env_origins_curriculum`: levels `U{0..=max_init_level}` (or every env
    /// at `init_level`), column `floor(i · num_cols / num_envs)`.
    pub fn new<R: Rng + ?Sized>(num_envs: usize, spec: &TerrainSpec, rng: &mut R) -> Curriculum {
        let max_init = spec.max_init_level.min(spec.num_rows.saturating_sub(1));
        let levels = (0..num_envs)
            .map(|_| match spec.init_level {
                Some(level) => level,
                None => rng.random_range(0..=max_init),
            })
            .collect();
        let cols = (0..num_envs)
            .map(|i| (i * spec.num_cols / num_envs.max(1)).min(spec.num_cols - 1))
            .collect();
        Curriculum {
            levels,
            cols,
            num_rows: spec.num_rows,
            num_cols: spec.num_cols,
            tile_size: spec.tile_size,
            enabled: spec.curriculum,
        }
    }

    /// Number of envs.
    pub fn len(&self) -> usize {
        self.levels.len()
    }

    /// True with no envs.
    pub fn is_empty(&self) -> bool {
        self.levels.is_empty()
    }

    /// Whether levels move.
    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// Level (row) of env `env`.
    pub fn level(&self, env: usize) -> usize {
        self.levels[env]
    }

    /// Column of env `env`.
    pub fn col(&self, env: usize) -> usize {
        self.cols[env]
    }

    /// Sets an env's level (clamped), e.g. for evaluation on a chosen level.
    pub fn set_level(&mut self, env: usize, level: usize) {
        self.levels[env] = level.min(self.num_rows - 1);
    }

    /// IsaacLab `terrain_levels_vel`, called when env `env` resets: `distance` is the xy distance
    /// walked from its tile origin, `command_xy_norm` the norm of its current xy velocity command.
    /// Promote when `distance > tile_size / 2`; demote when `distance < ‖cmd_xy‖ ·
    /// episode_length_s · 0.5` and not promoted; a level past the last is redrawn uniformly from
    /// `0..num_rows`; levels never go below 0. No-op when the curriculum is disabled.
    pub fn update<R: Rng + ?Sized>(
        &mut self,
        env: usize,
        distance: f32,
        command_xy_norm: f32,
        episode_length_s: f32,
        rng: &mut R,
    ) -> LevelChange {
        if !self.enabled {
            return LevelChange::Kept;
        }
        let move_up = distance > 0.5 * self.tile_size;
        let move_down = !move_up && distance < command_xy_norm * episode_length_s * 0.5;
        let level = self.levels[env];
        if move_up {
            if level + 1 >= self.num_rows {
                self.levels[env] = rng.random_range(0..self.num_rows);
                LevelChange::Redrawn
            } else {
                self.levels[env] = level + 1;
                LevelChange::Promoted
            }
        } else if move_down {
            self.levels[env] = level.saturating_sub(1);
            if level == 0 {
                LevelChange::Kept
            } else {
                LevelChange::Demoted
            }
        } else {
            LevelChange::Kept
        }
    }

    /// Mean level over all envs (IsaacLab's logged `Curriculum/terrain_levels`).
    pub fn mean_level(&self) -> f32 {
        if self.levels.is_empty() {
            return 0.0;
        }
        self.levels.iter().sum::<usize>() as f32 / self.levels.len() as f32
    }

    /// Mean level per terrain type present: `(type, mean level, number of envs)`, in
    /// [`TerrainType::ALL`] order, written into `out` (no allocation); returns how many were written.
    pub fn mean_level_by_type(
        &self,
        terrain: &Terrain,
        out: &mut [(TerrainType, f32, usize); 7],
    ) -> usize {
        let mut sum = [0usize; 7];
        let mut cnt = [0usize; 7];
        for (l, c) in self.levels.iter().zip(&self.cols) {
            let t = terrain.tile_type(*c).index();
            sum[t] += l;
            cnt[t] += 1;
        }
        let mut k = 0;
        for (i, t) in TerrainType::ALL.iter().enumerate() {
            if cnt[i] > 0 {
                out[k] = (*t, sum[i] as f32 / cnt[i] as f32, cnt[i]);
                k += 1;
            }
        }
        k
    }

    /// Number of columns of the terrain this curriculum was built for.
    pub fn num_cols(&self) -> usize {
        self.num_cols
    }
}

/// Grid samples `ix_lo..=ix_hi` × `iy_lo..=iy_hi` of one tile (a tile shares its edge samples with
/// its neighbours).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleRect {
    pub ix_lo: usize,
    pub ix_hi: usize,
    pub iy_lo: usize,
    pub iy_hi: usize,
}

/// The samples of the tile whose lower corner is `corner` (world), side `l`, on a grid at `origin`
/// with spacing `res` and `n` samples per axis.
fn sample_rect(corner: [f32; 2], l: f32, origin: [f32; 2], res: f32, n: [usize; 2]) -> SampleRect {
    let lo = |a: usize| ((corner[a] - origin[a]) / res - 1e-3).ceil().max(0.0) as usize;
    let hi = |a: usize| (((corner[a] + l - origin[a]) / res + 1e-3).floor() as usize).min(n[a] - 1);
    SampleRect {
        ix_lo: lo(0),
        ix_hi: hi(0),
        iy_lo: lo(1),
        iy_hi: hi(1),
    }
}

/// Vertices and triangles of a mesh under construction.
#[derive(Default)]
struct MeshBuilder {
    vertices: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl MeshBuilder {
    /// A planar quad, corners counter-clockwise seen from the side it faces.
    fn quad(&mut self, corners: [[f32; 3]; 4]) {
        let first = self.vertices.len() as u32;
        self.vertices.extend(corners);
        self.triangles
            .extend([[first, first + 1, first + 2], [first, first + 2, first + 3]]);
    }
}

#[cfg(test)]
mod tests;
