//! Collada (`.dae`) vertices, read as ROS reads a URDF's Collada mesh (rviz's mesh loader, MoveIt's
//! `geometric_shapes`), so that a hull here is the shape those tools show and plan with:
//!
//! - `<asset><unit meter>` scales every vertex (a file in millimetres says `meter="0.001"`);
//! - `<up_axis>` is ignored: rviz drops the root transform that would apply it, and vendors'
//!   files (Unitree's among them) are drawn right in rviz whatever they declare;
//! - the visual scene's node tree is walked (the scene `<scene>` instantiates, else the first),
//!   composing each node's `<matrix>`, `<translate>`, `<rotate>` and `<scale>` in document order,
//!   through `<instance_node>` references; every `<instance_geometry>` contributes its mesh's
//!   `POSITION` source under the node's transform. A file without a visual scene contributes
//!   every mesh untransformed.
//!
//! Only positions are read: faces, normals and materials do not change a convex hull.

use std::collections::HashMap;

use glamx::Mat4;
use xml::reader::{EventReader, ParserConfig, XmlEvent};

use crate::math::Vec3;

/// Deepest node nesting followed (an `<instance_node>` cycle is an error, not a hang).
const MAX_NODE_DEPTH: usize = 64;

/// Elements whose text is read; every other element's text is skipped (index lists are most of
/// a file).
const TEXT_ELEMENTS: [&str; 6] = [
    "float_array",
    "matrix",
    "translate",
    "rotate",
    "scale",
    "up_axis",
];

/// An element of the document: local name, attributes, children, and the text of
/// [`TEXT_ELEMENTS`].
#[derive(Debug, Default)]
struct Element {
    name: String,
    attributes: Vec<(String, String)>,
    children: Vec<Element>,
    text: String,
}

impl Element {
    fn attribute(&self, name: &str) -> Option<&str> {
        self.attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    fn child(&self, name: &str) -> Option<&Element> {
        self.children.iter().find(|c| c.name == name)
    }

    fn children_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Element> {
        self.children.iter().filter(move |c| c.name == name)
    }

    /// Every descendant (depth first) named `name`.
    fn descendants<'a>(&'a self, name: &str, out: &mut Vec<&'a Element>) {
        for c in &self.children {
            if c.name == name {
                out.push(c);
            }
            c.descendants(name, out);
        }
    }
}

/// Every vertex position of the Collada document `text`, in metres (see the module doc), or why
/// there are none.
pub fn vertices(text: &str) -> Result<Vec<Vec3>, String> {
    let root = parse(text)?;
    if root.name != "COLLADA" {
        return Err(format!(
            "not Collada: the root element is <{}>, not <COLLADA>",
            root.name
        ));
    }
    let meter = match root.child("asset").and_then(|a| a.child("unit")) {
        Some(unit) => match unit.attribute("meter") {
            Some(m) => m
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|m| m.is_finite() && *m > 0.0)
                .ok_or_else(|| format!("Collada <unit meter=\"{m}\"> is not a positive number"))?,
            None => 1.0,
        },
        None => 1.0,
    };
    let mut geometries = Vec::new();
    root.descendants("geometry", &mut geometries);
    let mut meshes: HashMap<&str, Vec<Vec3>> = HashMap::new();
    let mut unnamed = Vec::new();
    for g in geometries {
        let Some(mesh) = g.child("mesh") else {
            continue;
        };
        let positions = mesh_positions(mesh).map_err(|why| {
            format!(
                "Collada geometry `{}`: {why}",
                g.attribute("id").unwrap_or("")
            )
        })?;
        match g.attribute("id") {
            Some(id) => {
                meshes.insert(id, positions);
            }
            None => unnamed.push(positions),
        }
    }
    if meshes.is_empty() && unnamed.is_empty() {
        return Err("Collada without a <geometry> holding a <mesh>".into());
    }
    let mut library_nodes = Vec::new();
    root.descendants("node", &mut library_nodes);
    let nodes: HashMap<&str, &Element> = library_nodes
        .into_iter()
        .filter_map(|n| Some((n.attribute("id")?, n)))
        .collect();
    let mut scenes = Vec::new();
    root.descendants("visual_scene", &mut scenes);
    let wanted = root
        .child("scene")
        .and_then(|s| s.child("instance_visual_scene"))
        .and_then(|i| i.attribute("url"))
        .map(|url| url.trim_start_matches('#'));
    let scene = match wanted {
        Some(id) => Some(
            scenes
                .iter()
                .find(|s| s.attribute("id") == Some(id))
                .copied()
                .ok_or_else(|| {
                    format!("Collada <scene> names visual scene `{id}`, which is not there")
                })?,
        ),
        None => scenes.first().copied(),
    };
    let mut out = Vec::new();
    match scene {
        Some(scene) => {
            let walk = Walk {
                meshes: &meshes,
                nodes: &nodes,
            };
            for node in scene.children_named("node") {
                walk.node(node, Mat4::IDENTITY, 0, &mut out)?;
            }
        }
        None => {
            out.extend(meshes.values().flatten().copied());
            out.extend(unnamed.into_iter().flatten());
        }
    }
    if out.is_empty() {
        return Err("Collada whose visual scene instantiates no mesh".into());
    }
    Ok(out.into_iter().map(|v| v * meter).collect())
}

/// The scene walk's lookups.
struct Walk<'a> {
    meshes: &'a HashMap<&'a str, Vec<Vec3>>,
    nodes: &'a HashMap<&'a str, &'a Element>,
}

impl Walk<'_> {
    fn node(
        &self,
        node: &Element,
        parent: Mat4,
        depth: usize,
        out: &mut Vec<Vec3>,
    ) -> Result<(), String> {
        if depth > MAX_NODE_DEPTH {
            return Err(format!(
                "Collada nodes nest deeper than {MAX_NODE_DEPTH} (an <instance_node> cycle?)"
            ));
        }
        let mut transform = parent;
        for c in &node.children {
            let local = match c.name.as_str() {
                "matrix" => {
                    let m = numbers::<16>(c)?;
                    // Collada writes the matrix row by row; glam's arrays are column by column.
                    Mat4::from_cols_array(&m).transpose()
                }
                "translate" => Mat4::from_translation(Vec3::from_array(numbers::<3>(c)?)),
                "scale" => Mat4::from_scale(Vec3::from_array(numbers::<3>(c)?)),
                "rotate" => {
                    let [x, y, z, degrees] = numbers::<4>(c)?;
                    let axis = Vec3::new(x, y, z);
                    if axis.length_squared() == 0.0 {
                        if degrees == 0.0 {
                            continue;
                        }
                        return Err("Collada <rotate> about a zero axis".into());
                    }
                    Mat4::from_axis_angle(axis.normalize(), degrees.to_radians())
                }
                "lookat" | "skew" => {
                    return Err(format!("Collada <{}> transforms are not read", c.name));
                }
                _ => continue,
            };
            transform *= local;
        }
        for c in &node.children {
            match c.name.as_str() {
                "instance_geometry" => {
                    let id = reference(c)?;
                    let positions = self.meshes.get(id).ok_or_else(|| {
                        format!("Collada node instantiates geometry `{id}`, which has no mesh")
                    })?;
                    out.extend(positions.iter().map(|p| transform.transform_point3(*p)));
                }
                "instance_node" => {
                    let id = reference(c)?;
                    let target = self.nodes.get(id).ok_or_else(|| {
                        format!("Collada <instance_node> names node `{id}`, which is not there")
                    })?;
                    self.node(target, transform, depth + 1, out)?;
                }
                "node" => self.node(c, transform, depth + 1, out)?,
                _ => {}
            }
        }
        Ok(())
    }
}

/// The id an `<instance_*>`'s `url` points at (`#id`).
fn reference(instance: &Element) -> Result<&str, String> {
    instance
        .attribute("url")
        .map(|u| u.trim_start_matches('#'))
        .ok_or_else(|| format!("Collada <{}> without a url", instance.name))
}

/// A mesh's vertex positions: the source its `<vertices>` element names as `POSITION`, read
/// through that source's accessor (stride, offset, count).
fn mesh_positions(mesh: &Element) -> Result<Vec<Vec3>, String> {
    let source_id = mesh
        .child("vertices")
        .and_then(|v| {
            v.children_named("input")
                .find(|i| i.attribute("semantic") == Some("POSITION"))
        })
        .and_then(|i| i.attribute("source"))
        .map(|s| s.trim_start_matches('#'))
        .ok_or("its <mesh> has no <vertices> with a POSITION input")?;
    let source = mesh
        .children_named("source")
        .find(|s| s.attribute("id") == Some(source_id))
        .ok_or_else(|| format!("its POSITION source `{source_id}` is not in the mesh"))?;
    let array = source
        .child("float_array")
        .ok_or_else(|| format!("source `{source_id}` has no <float_array>"))?;
    let floats = array
        .text
        .split_whitespace()
        .map(|w| w.parse::<f32>())
        .collect::<Result<Vec<f32>, _>>()
        .map_err(|e| format!("source `{source_id}`: a <float_array> value is not a number: {e}"))?;
    let accessor = source
        .child("technique_common")
        .and_then(|t| t.child("accessor"));
    let attr = |name: &str, default: usize| -> Result<usize, String> {
        match accessor.and_then(|a| a.attribute(name)) {
            Some(v) => v.trim().parse().map_err(|_| {
                format!("source `{source_id}`: accessor {name}=\"{v}\" is not a count")
            }),
            None => Ok(default),
        }
    };
    let stride = attr("stride", 3)?;
    if stride < 3 {
        return Err(format!(
            "source `{source_id}`: accessor stride {stride} is less than the 3 of a position"
        ));
    }
    let offset = attr("offset", 0)?;
    // Positions whose three values are in the array (the last needs 3 values, not a stride).
    let available = match floats.len().checked_sub(offset + 3) {
        Some(rest) => rest / stride + 1,
        None => 0,
    };
    let count = attr("count", available)?;
    if count > available {
        return Err(format!(
            "source `{source_id}`: its accessor reads {count} positions, the array holds {available}"
        ));
    }
    Ok((0..count)
        .map(|i| {
            let at = offset + i * stride;
            Vec3::new(floats[at], floats[at + 1], floats[at + 2])
        })
        .collect())
}

/// Exactly `N` numbers from an element's text.
fn numbers<const N: usize>(e: &Element) -> Result<[f32; N], String> {
    let values: Vec<f32> = e
        .text
        .split_whitespace()
        .map(str::parse)
        .collect::<Result<_, _>>()
        .map_err(|_| {
            format!(
                "Collada <{}> `{}` is not {N} numbers",
                e.name,
                e.text.trim()
            )
        })?;
    values
        .try_into()
        .map_err(|v: Vec<f32>| format!("Collada <{}> has {} numbers, not {N}", e.name, v.len()))
}

/// The document as a tree of [`Element`]s.
fn parse(text: &str) -> Result<Element, String> {
    let config = ParserConfig::new()
        .trim_whitespace(false)
        .ignore_comments(true);
    let mut stack: Vec<Element> = Vec::new();
    for event in EventReader::new_with_config(text.as_bytes(), config) {
        match event.map_err(|e| format!("malformed Collada XML: {e}"))? {
            XmlEvent::StartElement {
                name, attributes, ..
            } => stack.push(Element {
                name: name.local_name,
                attributes: attributes
                    .into_iter()
                    .map(|a| (a.name.local_name, a.value))
                    .collect(),
                ..Element::default()
            }),
            XmlEvent::Characters(t) | XmlEvent::CData(t) => {
                if let Some(top) = stack.last_mut()
                    && TEXT_ELEMENTS.contains(&top.name.as_str())
                {
                    top.text.push_str(&t);
                }
            }
            XmlEvent::EndElement { .. } => {
                let done = stack
                    .pop()
                    .ok_or("malformed Collada XML: unbalanced end tag")?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(done),
                    None => return Ok(done),
                }
            }
            _ => {}
        }
    }
    Err("malformed Collada XML: the document ends inside an element".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit cube's 8 corners as one mesh, placed by `node` (the node's transform elements) in
    /// a file whose unit is `meter`.
    fn cube_dae(meter: &str, node: &str) -> String {
        let mut corners = String::new();
        for i in 0..8 {
            let c = |bit: usize| if i & bit == 0 { "0" } else { "1" };
            corners.push_str(&format!("{} {} {} ", c(1), c(2), c(4)));
        }
        format!(
            r##"<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="unit" meter="{meter}"/><up_axis>Y_UP</up_axis></asset>
  <library_geometries>
    <geometry id="cube-mesh" name="cube">
      <mesh>
        <source id="cube-positions">
          <float_array id="cube-positions-array" count="24">{corners}</float_array>
          <technique_common>
            <accessor source="#cube-positions-array" count="8" stride="3">
              <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
        <vertices id="cube-vertices"><input semantic="POSITION" source="#cube-positions"/></vertices>
        <triangles count="1"><input semantic="VERTEX" source="#cube-vertices" offset="0"/><p>0 1 2</p></triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="Scene" name="Scene">
      <node id="cube" name="cube">{node}<instance_geometry url="#cube-mesh"/></node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#Scene"/></scene>
</COLLADA>"##
        )
    }

    fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
        let lo = points.iter().fold(Vec3::INFINITY, |a, p| a.min(*p));
        let hi = points.iter().fold(Vec3::NEG_INFINITY, |a, p| a.max(*p));
        (lo, hi)
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn the_unit_scales_and_node_transforms_compose_in_document_order() {
        // Millimetres; scaled by 10 then moved 5 mm along x: the cube spans 5..15 mm in x.
        let text = cube_dae(
            "0.001",
            "<translate>5 0 0</translate><scale>10 10 10</scale>",
        );
        let v = vertices(&text).unwrap();
        assert_eq!(v.len(), 8);
        let (lo, hi) = bounds(&v);
        assert!(close(lo, Vec3::new(0.005, 0.0, 0.0)), "{lo}");
        assert!(close(hi, Vec3::new(0.015, 0.01, 0.01)), "{hi}");
        // A row-major matrix: the same translation written as its last column.
        let text = cube_dae("1", "<matrix>1 0 0 2  0 1 0 0  0 0 1 0  0 0 0 1</matrix>");
        let (lo, _) = bounds(&vertices(&text).unwrap());
        assert!(close(lo, Vec3::new(2.0, 0.0, 0.0)), "{lo}");
        // 90 degrees about z takes +x to +y; `up_axis` (Y_UP here) changes nothing.
        let text = cube_dae("1", "<rotate>0 0 1 90</rotate>");
        let (lo, hi) = bounds(&vertices(&text).unwrap());
        assert!(close(lo, Vec3::new(-1.0, 0.0, 0.0)), "{lo}");
        assert!(close(hi, Vec3::new(0.0, 1.0, 1.0)), "{hi}");
    }

    #[test]
    fn nested_and_referenced_nodes_carry_their_parents_transform() {
        let text = cube_dae("1", "<translate>1 0 0</translate>").replace(
            r##"<instance_geometry url="#cube-mesh"/></node>"##,
            r##"<node id="inner"><translate>0 2 0</translate><instance_geometry url="#cube-mesh"/></node><instance_node url="#shared"/></node>"##,
        );
        let text = text.replace(
            "<library_visual_scenes>",
            r##"<library_nodes><node id="shared"><translate>0 0 3</translate><instance_geometry url="#cube-mesh"/></node></library_nodes><library_visual_scenes>"##,
        );
        let v = vertices(&text).unwrap();
        assert_eq!(v.len(), 16);
        assert!(v.contains(&Vec3::new(1.0, 2.0, 0.0)), "{v:?}");
        assert!(v.contains(&Vec3::new(1.0, 0.0, 3.0)), "{v:?}");
        assert!(!v.contains(&Vec3::new(0.0, 0.0, 0.0)), "{v:?}");
    }

    #[test]
    fn bad_documents_say_what_is_wrong() {
        let err = |text: &str| vertices(text).unwrap_err();
        assert!(err("<COLLADA/>").contains("<geometry>"));
        assert!(err("<svg/>").contains("not Collada"));
        assert!(err("<COLLADA><asset>").contains("malformed"));
        let cube = cube_dae("1", "");
        assert!(err(&cube.replace("meter=\"1\"", "meter=\"-1\"")).contains("unit"));
        assert!(err(&cube.replace("0 0 0 1 0 0", "0 0 0 one 0 0")).contains("not a number"));
        assert!(err(&cube.replace("count=\"8\"", "count=\"9\"")).contains("holds 8"));
        assert!(err(&cube.replace("#cube-mesh", "#other")).contains("`other`"));
        let cycle = cube.replace(
            "<instance_geometry",
            r##"<instance_node url="#cube"/><instance_geometry"##,
        );
        assert!(err(&cycle).contains("cycle"));
    }
}
