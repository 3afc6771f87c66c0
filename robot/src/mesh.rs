//! Collision meshes read for [`crate::urdf::load_urdf_file`]: a `<mesh>` whose file is found
//! beside the URDF becomes a convex-hull collider ([`crate::model::ShapeSpec::ConvexHull`]).
//!
//! - Formats: binary and ASCII STL, Wavefront OBJ (its `v` lines only), Collada (`.dae`, its
//!   mesh positions placed by its scene's node transforms and scaled by its unit, as ROS reads it:
//!   [`collada`]). Any other format is not read: the loader's stand-ins replace it, with a
//!   warning saying so.
//! - Paths ([`resolve`]): a plain path is relative to the URDF's directory; `file://` is an
//!   absolute path; `package://pkg/rest` is the first file found of `<urdf dir>/rest`,
//!   `<urdf dir>/../rest`, then `<d>/pkg/rest` for `d` the URDF's directory and each of its
//!   ancestors (a package's `urdf/` and `meshes/` side by side, or a ROS workspace's `src/pkg`).
//! - Points ([`hull_points`]): the mesh's distinct vertices times its `scale`, on a
//!   [`HULL_RESOLUTION_M`] grid (what an added robot's description records: [`MeshHull`]). More than
//!   [`MAX_HULL_POINTS`] are reduced to the most extreme vertex along each of that many fixed
//!   directions (the six axis directions among them, so the bounding box stays exact): contact
//!   cost in the simulator grows with the hull's size, and a vendor's 50,000-triangle shank needs
//!   no more for a foot-scale collision. A hull needs volume: fewer than 4 distinct vertices, all
//!   of them within [`MIN_HULL_THICKNESS`] of their span of one line or plane, non-finite
//!   coordinates, or a span over [`MAX_HULL_SPAN_M`] (a millimetre mesh without its `scale`) are
//!   refused with the reason.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::math::Vec3;

pub mod collada;

/// Most points a hull collider keeps.
pub const MAX_HULL_POINTS: usize = 128;
/// Largest mesh file read (bytes): vendor meshes are 0.1–20 MB.
pub const MAX_MESH_BYTES: u64 = 128 * 1024 * 1024;
/// A mesh whose vertices all lie within this fraction of their span of one line or plane is
/// flat: no hull (the simulator's hull builder reads such point sets as lower-dimensional).
pub const MIN_HULL_THICKNESS: f32 = 0.01;
/// Smallest span of a hull (m): below it the mesh is a point.
pub const MIN_HULL_SPAN_M: f32 = 1e-4;
/// Largest span of a hull (m): no robot link is longer.
pub const MAX_HULL_SPAN_M: f32 = 10.0;
/// Hull points are rounded to this grid (m), so that a robot description lists them readably and
/// the hull read back from it is the one read from the mesh.
pub const HULL_RESOLUTION_M: f32 = 1e-4;

/// The hull of one collision mesh as a URDF names it: what `l3p robots add` records in an added
/// robot's description ([`crate::added::RobotDescription::mesh_hulls`]), so that the robot keeps
/// its hulls where only the URDF's text travels ([`crate::urdf::load_urdf_str_with_hulls`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshHull {
    /// The `<mesh filename>`, exactly as the URDF writes it.
    pub file: String,
    /// The `<mesh scale>` (`[1, 1, 1]` when the URDF gives none).
    pub scale: [f32; 3],
    /// The hull's points ([`hull_points`]: scale applied, metres, in the mesh's frame), at most
    /// [`MAX_HULL_POINTS`].
    pub points: Vec<[f32; 3]>,
}

/// The file a URDF `<mesh filename>` names, for a URDF in `urdf_dir`; or why none is found.
pub fn resolve(filename: &str, urdf_dir: &Path) -> Result<PathBuf, String> {
    if let Some(rest) = filename.strip_prefix("package://") {
        let Some((package, inside)) = rest.split_once('/') else {
            return Err("a `package://` path needs a package name and a path in it".into());
        };
        let mut tried = vec![urdf_dir.join(inside), urdf_dir.join("..").join(inside)];
        tried.extend(urdf_dir.ancestors().map(|d| d.join(package).join(inside)));
        return match tried.iter().find(|p| p.is_file()) {
            Some(found) => Ok(found.clone()),
            None => Err(format!(
                "not found (tried {})",
                tried
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
        };
    }
    let path = match filename.strip_prefix("file://") {
        Some(absolute) => PathBuf::from(absolute),
        None if filename.contains("://") => {
            return Err("only `package://`, `file://` and plain paths are resolved".into());
        }
        None => urdf_dir.join(filename),
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(format!("no file at {}", path.display()))
    }
}

/// The hull points (see [`hull_points`]) of the mesh `filename` scaled by `scale`, for a URDF in
/// `urdf_dir`; or why there are none, naming the file.
pub fn load_hull(filename: &str, scale: Vec3, urdf_dir: &Path) -> Result<Vec<Vec3>, String> {
    let path = resolve(filename, urdf_dir)?;
    read_vertices(&path)
        .and_then(|vertices| hull_points(&vertices, scale))
        .map_err(|why| format!("{}: {why}", path.display()))
}

/// Every vertex of the mesh file at `path` (duplicates included), or why it cannot be read.
pub fn read_vertices(path: &Path) -> Result<Vec<Vec3>, String> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if !matches!(ext.as_str(), "stl" | "obj" | "dae") {
        return Err(match ext.as_str() {
            "" => "no file extension: only STL, OBJ and Collada meshes are read".into(),
            other => format!("`.{other}` is not read: only STL, OBJ and Collada (.dae) meshes are"),
        });
    }
    let size = std::fs::metadata(path).map_err(|e| e.to_string())?.len();
    if size > MAX_MESH_BYTES {
        return Err(format!(
            "{size} bytes is more than the {MAX_MESH_BYTES} a mesh may have"
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    if ext == "stl" {
        return stl_vertices(&bytes);
    }
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| format!("{} is not UTF-8: {e}", ext.to_ascii_uppercase()))?;
    if ext == "dae" {
        collada::vertices(text)
    } else {
        obj_vertices(text)
    }
}

/// Binary STL: an 80-byte header, a little-endian `u32` triangle count, then 50 bytes per
/// triangle (normal, three vertices, attribute). Length is checked first: many binary files
/// start their header with `solid`, the ASCII keyword.
fn stl_vertices(bytes: &[u8]) -> Result<Vec<Vec3>, String> {
    const HEADER: usize = 84;
    const TRIANGLE: usize = 50;
    let count = bytes
        .get(80..HEADER)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as usize);
    if let Some(count) = count
        && count
            .checked_mul(TRIANGLE)
            .and_then(|b| b.checked_add(HEADER))
            == Some(bytes.len())
    {
        let f = |at: usize| {
            f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
        };
        let mut out = Vec::with_capacity(3 * count);
        for t in 0..count {
            // Skip the 12-byte normal.
            let first = HEADER + t * TRIANGLE + 12;
            for v in 0..3 {
                let at = first + 12 * v;
                out.push(Vec3::new(f(at), f(at + 4), f(at + 8)));
            }
        }
        return Ok(out);
    }
    let ascii = match std::str::from_utf8(bytes) {
        Ok(text) if text.trim_start().starts_with("solid") => ascii_stl_vertices(text),
        Ok(_) => Err("not ASCII STL (no `solid` keyword)".to_string()),
        Err(_) => Err("not ASCII STL (not text)".to_string()),
    };
    ascii.map_err(|why| match count {
        Some(count) => format!(
            "neither binary STL (its header counts {count} triangles, {} bytes, but the file has {}: truncated?) nor ASCII STL: {why}",
            HEADER as u64 + TRIANGLE as u64 * count as u64,
            bytes.len()
        ),
        None => format!(
            "{} bytes is too short for binary STL (84-byte header), and it is {why}",
            bytes.len()
        ),
    })
}

/// ASCII STL: the `vertex x y z` lines.
fn ascii_stl_vertices(text: &str) -> Result<Vec<Vec3>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if words.next() == Some("vertex") {
            out.push(three_numbers(words).ok_or_else(|| {
                format!("line {}: `{}` is not `vertex x y z`", i + 1, line.trim())
            })?);
        }
    }
    if out.is_empty() {
        return Err("ASCII STL without `vertex` lines".into());
    }
    Ok(out)
}

/// Wavefront OBJ: the `v x y z [w | r g b]` lines (faces, normals and materials are not needed
/// for a hull).
fn obj_vertices(text: &str) -> Result<Vec<Vec3>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if words.next() == Some("v") {
            out.push(
                three_numbers(words)
                    .ok_or_else(|| format!("line {}: `{}` is not `v x y z`", i + 1, line.trim()))?,
            );
        }
    }
    if out.is_empty() {
        return Err("OBJ without `v` lines".into());
    }
    Ok(out)
}

fn three_numbers<'a>(mut words: impl Iterator<Item = &'a str>) -> Option<Vec3> {
    let mut next = || words.next()?.parse::<f32>().ok();
    Some(Vec3::new(next()?, next()?, next()?))
}

/// The points whose convex hull is the collider for `vertices` scaled by `scale` (see the module
/// doc), or why they make no hull.
pub fn hull_points(vertices: &[Vec3], scale: Vec3) -> Result<Vec<Vec3>, String> {
    let mut seen = HashSet::new();
    let mut points = Vec::new();
    for v in vertices {
        let p = *v * scale;
        if !p.is_finite() {
            return Err(format!("vertex ({}, {}, {}) is not finite", v.x, v.y, v.z));
        }
        // Divided, not multiplied by the resolution: `k / 1e4` is the f32 nearest to k·0.1 mm,
        // so that rounding a rounded point changes nothing. Adding zero turns -0 into 0.
        let per_m = HULL_RESOLUTION_M.recip();
        let p = (p * per_m).round() / per_m + Vec3::ZERO;
        if seen.insert(p.to_array().map(f32::to_bits)) {
            points.push(p);
        }
    }
    if points.len() < 4 {
        return Err(format!(
            "{} distinct vertices: a hull needs 4 that are not in one plane",
            points.len()
        ));
    }
    if points.len() > MAX_HULL_POINTS {
        points = extreme_points(&points, MAX_HULL_POINTS);
    }
    check_volume(&points)?;
    Ok(points)
}

/// The corners of the convex hull of `points`, which lie in one plane with unit `normal`: its
/// 2-D hull (Andrew's monotone chain) in a basis of that plane, corners in order, collinear
/// points dropped. Where a hull is cut by a plane, the crossings of its point pairs fill the cut
/// face; only the face's corners are needed.
pub fn hull_in_plane(points: &[Vec3], normal: Vec3) -> Vec<Vec3> {
    let (a, b) = normal.any_orthonormal_pair();
    let mut flat: Vec<(f32, f32, Vec3)> = points.iter().map(|p| (p.dot(a), p.dot(b), *p)).collect();
    flat.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.total_cmp(&q.1)));
    flat.dedup_by(|p, q| p.0 == q.0 && p.1 == q.1);
    if flat.len() < 3 {
        return flat.into_iter().map(|p| p.2).collect();
    }
    let turn = |o: &(f32, f32, Vec3), p: &(f32, f32, Vec3), q: &(f32, f32, Vec3)| {
        (p.0 - o.0) * (q.1 - o.1) - (p.1 - o.1) * (q.0 - o.0)
    };
    let mut hull: Vec<(f32, f32, Vec3)> = Vec::with_capacity(2 * flat.len());
    for pass in [flat.clone(), flat.iter().rev().copied().collect::<Vec<_>>()] {
        let start = hull.len();
        for p in pass {
            while hull.len() >= start + 2
                && turn(&hull[hull.len() - 2], &hull[hull.len() - 1], &p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        // The last point of each chain is the first of the next.
        hull.pop();
    }
    hull.into_iter().map(|p| p.2).collect()
}

/// The most extreme of `points` along each of `n` fixed directions, without repeats: the six
/// axis directions, then a Fibonacci lattice on the sphere.
fn extreme_points(points: &[Vec3], n: usize) -> Vec<Vec3> {
    let mut directions = vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
    let lattice = n.saturating_sub(directions.len());
    let golden_angle = std::f32::consts::PI * (3.0 - 5.0_f32.sqrt());
    for i in 0..lattice {
        let z = 1.0 - 2.0 * (i as f32 + 0.5) / lattice as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let a = golden_angle * i as f32;
        directions.push(Vec3::new(r * a.cos(), r * a.sin(), z));
    }
    let mut chosen: Vec<usize> = directions
        .iter()
        .map(|d| {
            let mut best = 0;
            for (i, p) in points.iter().enumerate() {
                if p.dot(*d) > points[best].dot(*d) {
                    best = i;
                }
            }
            best
        })
        .collect();
    chosen.sort_unstable();
    chosen.dedup();
    chosen.into_iter().map(|i| points[i]).collect()
}

/// Refuses point sets without volume: a point, a line or a plane (within [`MIN_HULL_THICKNESS`]
/// of the span), or larger than any link.
fn check_volume(points: &[Vec3]) -> Result<(), String> {
    let farthest = |from: &dyn Fn(Vec3) -> f32| {
        points
            .iter()
            .copied()
            .max_by(|a, b| from(*a).total_cmp(&from(*b)))
            .unwrap_or(Vec3::ZERO)
    };
    let a = points[0];
    let b = farthest(&|p| p.distance(a));
    let c = farthest(&|p| p.distance(b));
    let span = c.distance(b);
    if span < MIN_HULL_SPAN_M {
        return Err(format!(
            "all vertices lie within {span:.2e} m of each other (a point)"
        ));
    }
    if span > MAX_HULL_SPAN_M {
        return Err(format!(
            "it spans {span:.1} m, more than any robot link (a mesh in millimetres without `scale`?)"
        ));
    }
    let axis = (c - b) / span;
    let off_line = |p: Vec3| (p - b).reject_from_normalized(axis).length();
    let d = farthest(&off_line);
    if off_line(d) < MIN_HULL_THICKNESS * span {
        return Err(format!(
            "its vertices lie on one line (within {:.2e} m over {span:.3} m): no volume",
            off_line(d)
        ));
    }
    let normal = axis.cross(d - b).normalize();
    let off_plane = |p: Vec3| (p - b).dot(normal).abs();
    let e = farthest(&off_plane);
    if off_plane(e) < MIN_HULL_THICKNESS * span {
        return Err(format!(
            "it is flat: its vertices lie in one plane (within {:.2e} m over {span:.3} m)",
            off_plane(e)
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(n: usize) -> Vec<Vec3> {
        // An n x n x n grid of points filling the unit cube (corners included).
        let s = |i: usize| i as f32 / (n - 1) as f32;
        let mut out = Vec::new();
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    out.push(Vec3::new(s(i), s(j), s(k)));
                }
            }
        }
        out
    }

    #[test]
    fn many_vertices_are_reduced_to_extreme_ones_keeping_the_bounding_box() {
        let points = hull_points(&cube(12), Vec3::new(0.1, 0.2, 0.3)).unwrap();
        assert!(points.len() <= MAX_HULL_POINTS, "{}", points.len());
        let lo = points.iter().fold(Vec3::INFINITY, |a, p| a.min(*p));
        let hi = points.iter().fold(Vec3::NEG_INFINITY, |a, p| a.max(*p));
        assert_eq!(lo, Vec3::ZERO);
        assert!((hi - Vec3::new(0.1, 0.2, 0.3)).length() < 1e-6, "{hi}");
    }

    #[test]
    fn points_are_rounded_to_the_grid_and_rounding_again_changes_nothing() {
        let jitter: Vec<Vec3> = cube(3)
            .into_iter()
            .map(|p| p * 0.0123456 - Vec3::splat(0.00001))
            .collect();
        let points = hull_points(&jitter, Vec3::ONE).unwrap();
        // -0.00001 m rounds to 0 (not -0), 0.0123456 - 0.00001 to 0.0123.
        assert!(points.contains(&Vec3::ZERO), "{points:?}");
        assert!(points.iter().all(|p| p.x.is_sign_positive()), "{points:?}");
        assert!(points.contains(&Vec3::splat(0.0123)), "{points:?}");
        assert_eq!(hull_points(&points, Vec3::ONE).unwrap(), points);
    }

    #[test]
    fn point_line_plane_and_non_finite_sets_are_refused() {
        let flat: Vec<Vec3> = cube(3)
            .into_iter()
            .map(|p| p * Vec3::new(1.0, 1.0, 0.0))
            .collect();
        assert!(hull_points(&flat, Vec3::ONE).unwrap_err().contains("flat"));
        let line: Vec<Vec3> = (0..9).map(|i| Vec3::X * i as f32 * 0.01).collect();
        assert!(hull_points(&line, Vec3::ONE).unwrap_err().contains("line"));
        let point = vec![Vec3::splat(0.1); 8];
        assert!(
            hull_points(&point, Vec3::ONE)
                .unwrap_err()
                .contains("distinct")
        );
        let mut odd = cube(2);
        odd[3].y = f32::NAN;
        assert!(
            hull_points(&odd, Vec3::ONE)
                .unwrap_err()
                .contains("not finite")
        );
        let huge = hull_points(&cube(2), Vec3::splat(1000.0)).unwrap_err();
        assert!(huge.contains("millimetres"), "{huge}");
    }

    #[test]
    fn stl_length_decides_binary_even_when_the_header_says_solid() {
        let mut bytes = b"solid but binary".to_vec();
        bytes.resize(80, 0);
        bytes.extend(1u32.to_le_bytes());
        bytes.extend([0u8; 12]);
        for v in [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0] {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend([0u8; 2]);
        let v = stl_vertices(&bytes).unwrap();
        assert_eq!(
            v,
            [
                Vec3::new(1.0, 2.0, 3.0),
                Vec3::new(4.0, 5.0, 6.0),
                Vec3::new(7.0, 8.0, 9.0)
            ]
        );
        let cut = stl_vertices(&bytes[..100]).unwrap_err();
        assert!(cut.contains("truncated"), "{cut}");
    }
}
