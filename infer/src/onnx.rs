//! ONNX form of an export ([`DeployPolicy::to_onnx`]), for runtimes that deploy rsl_rl / IsaacLab
//! policies as ONNX (onnxruntime, TensorRT; unitree_rl_gym and unitree_rl_lab load `policy.onnx`).
//!
//! One `ModelProto` (IR version [`ONNX_IR_VERSION`], default-domain opset [`ONNX_OPSET`], producer
//! `l3p`), its protobuf written by hand (no protobuf crate; the same few wire types as the
//! TensorBoard writer in `l3p-learner`):
//! - input [`ONNX_INPUT`] `[batch, obs_dim]` float32 (`batch` symbolic), output [`ONNX_OUTPUT`]
//!   `[batch, action_dim]` float32: the action MEAN, as [`DeployPolicy::act`] computes it;
//! - per export layer a `Gemm` (`transB = 1` on the `[out, in]` weight) and, where the layer is
//!   `elu`, an `Elu` (α = 1); weights and biases are initializers named as the safetensors tensors
//!   (`<layer>.weight`, `<layer>.bias`), little-endian f32 in `raw_data`;
//! - `metadata_props`: the export's JSON config under `l3p_export` (the same JSON as `policy.json`,
//!   with `io`, the controller contract) and, for convenience, `format`, `robot`, `arch`, `obs_dim`,
//!   `action_dim`, `action_scale` and `action_std` (a JSON list: the Gaussian std, which the graph
//!   does not use).
//!
//! The bytes depend on the export alone (fields and metadata in a fixed order).

use crate::PolicyError;
use crate::export::{DeployPolicy, EXPORT_METADATA_KEY};

/// ONNX IR version written (ONNX 1.10+ reads it).
pub const ONNX_IR_VERSION: u64 = 8;
/// Opset of the default (`ai.onnx`) domain.
pub const ONNX_OPSET: u64 = 17;
/// Name of the graph input (`[batch, obs_dim]`).
pub const ONNX_INPUT: &str = "obs";
/// Name of the graph output (`[batch, action_dim]`, action means).
pub const ONNX_OUTPUT: &str = "actions";
/// Symbolic name of the batch dimension.
pub const ONNX_BATCH_DIM: &str = "batch";

/// `TensorProto.DataType.FLOAT`.
const FLOAT: u64 = 1;
/// `AttributeProto.AttributeType` FLOAT and INT.
const ATTR_FLOAT: u64 = 1;
const ATTR_INT: u64 = 2;

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Protobuf field key: `field << 3 | wire type` (0 varint, 2 length-delimited, 5 32-bit).
fn put_key(out: &mut Vec<u8>, field: u32, wire_type: u8) {
    put_varint(out, ((field as u64) << 3) | wire_type as u64);
}

fn put_uint(out: &mut Vec<u8>, field: u32, v: u64) {
    put_key(out, field, 0);
    put_varint(out, v);
}

fn put_f32(out: &mut Vec<u8>, field: u32, v: f32) {
    put_key(out, field, 5);
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_bytes(out: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(out, field, 2);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

fn put_str(out: &mut Vec<u8>, field: u32, s: &str) {
    put_bytes(out, field, s.as_bytes());
}

/// `StringStringEntryProto { key = 1, value = 2 }`.
fn string_entry(key: &str, value: &str) -> Vec<u8> {
    let mut e = Vec::new();
    put_str(&mut e, 1, key);
    put_str(&mut e, 2, value);
    e
}

/// An attribute of a node (`AttributeProto`: name 1, f 2, i 3, type 20).
enum Attr {
    Float(f32),
    Int(u64),
}

fn attribute(name: &str, value: &Attr) -> Vec<u8> {
    let mut a = Vec::new();
    put_str(&mut a, 1, name);
    match *value {
        Attr::Float(f) => {
            put_f32(&mut a, 2, f);
            put_uint(&mut a, 20, ATTR_FLOAT);
        }
        Attr::Int(i) => {
            put_uint(&mut a, 3, i);
            put_uint(&mut a, 20, ATTR_INT);
        }
    }
    a
}

/// `NodeProto` (input 1, output 2, name 3, op_type 4, attribute 5) in the default domain.
fn node(name: &str, op: &str, inputs: &[&str], output: &str, attrs: &[(&str, Attr)]) -> Vec<u8> {
    let mut n = Vec::new();
    for i in inputs {
        put_str(&mut n, 1, i);
    }
    put_str(&mut n, 2, output);
    put_str(&mut n, 3, name);
    put_str(&mut n, 4, op);
    for (k, v) in attrs {
        put_bytes(&mut n, 5, &attribute(k, v));
    }
    n
}

/// A float `TensorProto` (dims 1, data_type 2, name 8, raw_data 9).
fn initializer(name: &str, dims: &[usize], values: &[f32]) -> Vec<u8> {
    let mut t = Vec::with_capacity(values.len() * 4 + name.len() + 16);
    for &d in dims {
        put_uint(&mut t, 1, d as u64);
    }
    put_uint(&mut t, 2, FLOAT);
    put_str(&mut t, 8, name);
    let raw: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    put_bytes(&mut t, 9, &raw);
    t
}

/// A float tensor `ValueInfoProto` of shape `[batch, width]`: name 1, type 2 →
/// `TypeProto.tensor_type` 1 → { elem_type 1, shape 2 → dim 1 → { dim_value 1 | dim_param 2 } }.
fn batch_tensor_info(name: &str, width: usize) -> Vec<u8> {
    let mut batch = Vec::new();
    put_str(&mut batch, 2, ONNX_BATCH_DIM);
    let mut cols = Vec::new();
    put_uint(&mut cols, 1, width as u64);
    let mut shape = Vec::new();
    put_bytes(&mut shape, 1, &batch);
    put_bytes(&mut shape, 1, &cols);
    let mut tensor = Vec::new();
    put_uint(&mut tensor, 1, FLOAT);
    put_bytes(&mut tensor, 2, &shape);
    let mut ty = Vec::new();
    put_bytes(&mut ty, 1, &tensor);
    let mut info = Vec::new();
    put_str(&mut info, 1, name);
    put_bytes(&mut info, 2, &ty);
    info
}

impl DeployPolicy {
    /// The policy as a serialised ONNX `ModelProto` (see the [module docs](crate::onnx)): `obs`
    /// `[batch, obs_dim]` → `actions` `[batch, action_dim]`, the same action means as
    /// [`act`](Self::act), with the export's JSON config in the model's metadata. Deterministic.
    pub fn to_onnx(&self) -> Result<Vec<u8>, PolicyError> {
        let cfg = &self.config;
        let json = |e: serde_json::Error| PolicyError::Export(e.to_string());

        let mut graph = Vec::new();
        let mut initializers = Vec::new();
        let mut x = ONNX_INPUT.to_string();
        let last = cfg.layers.len() - 1;
        for (k, (layer, w, b)) in self.layer_tensors().enumerate() {
            let elu = layer.activation == "elu";
            let name_of = |op: &str, is_out: bool| {
                if is_out {
                    ONNX_OUTPUT.to_string()
                } else {
                    format!("{}/{op}", layer.name)
                }
            };
            let (wn, bn) = (
                format!("{}.weight", layer.name),
                format!("{}.bias", layer.name),
            );
            let gemm_out = name_of("Gemm", k == last && !elu);
            graph.extend(node_field(&node(
                &format!("{}/Gemm", layer.name),
                "Gemm",
                &[&x, &wn, &bn],
                &gemm_out,
                &[("transB", Attr::Int(1))],
            )));
            x = gemm_out;
            if elu {
                let elu_out = name_of("Elu", k == last);
                graph.extend(node_field(&node(
                    &format!("{}/Elu", layer.name),
                    "Elu",
                    &[&x],
                    &elu_out,
                    &[("alpha", Attr::Float(1.0))],
                )));
                x = elu_out;
            }
            put_bytes(
                &mut initializers,
                5,
                &initializer(&wn, &[layer.output, layer.input], &w),
            );
            put_bytes(&mut initializers, 5, &initializer(&bn, &[layer.output], b));
        }
        put_str(&mut graph, 2, "l3p_policy");
        graph.extend_from_slice(&initializers);
        put_str(
            &mut graph,
            10,
            "action means of an l3p policy (l3p-export-v1); metadata `l3p_export` holds its config",
        );
        put_bytes(&mut graph, 11, &batch_tensor_info(ONNX_INPUT, cfg.obs_dim));
        put_bytes(
            &mut graph,
            12,
            &batch_tensor_info(ONNX_OUTPUT, cfg.action_dim),
        );

        let mut opset = Vec::new();
        put_str(&mut opset, 1, "");
        put_uint(&mut opset, 2, ONNX_OPSET);

        let metadata = [
            (
                EXPORT_METADATA_KEY,
                serde_json::to_string(cfg).map_err(json)?,
            ),
            ("format", cfg.format.clone()),
            ("robot", cfg.robot.clone()),
            ("arch", cfg.arch.clone()),
            ("obs_dim", cfg.obs_dim.to_string()),
            ("action_dim", cfg.action_dim.to_string()),
            ("action_scale", cfg.action_scale.to_string()),
            (
                "action_std",
                serde_json::to_string(self.std()).map_err(json)?,
            ),
        ];

        let mut model = Vec::with_capacity(graph.len() + 8192);
        put_uint(&mut model, 1, ONNX_IR_VERSION);
        put_str(&mut model, 2, "l3p");
        put_str(&mut model, 3, env!("CARGO_PKG_VERSION"));
        put_bytes(&mut model, 7, &graph);
        put_bytes(&mut model, 8, &opset);
        for (k, v) in &metadata {
            put_bytes(&mut model, 14, &string_entry(k, v));
        }
        Ok(model)
    }
}

/// `GraphProto.node` (field 1) holding `node`.
fn node_field(node: &[u8]) -> Vec<u8> {
    let mut f = Vec::with_capacity(node.len() + 4);
    put_bytes(&mut f, 1, node);
    f
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;
    use std::path::Path;

    use super::*;
    use crate::ExportConfig;

    const EXPORT_DIR: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/a1-flat-session27/policy"
    );

    fn policy() -> DeployPolicy {
        DeployPolicy::load(Path::new(EXPORT_DIR)).unwrap()
    }

    // A minimal protobuf reader: enough of the wire format to read back what `to_onnx` writes.
    enum Value<'a> {
        Varint(u64),
        Bytes(&'a [u8]),
        Fixed32([u8; 4]),
    }

    fn fields(mut data: &[u8]) -> Vec<(u32, Value<'_>)> {
        fn varint(data: &mut &[u8]) -> u64 {
            let mut v = 0u64;
            for shift in (0..64).step_by(7) {
                let (&b, rest) = data.split_first().expect("truncated varint");
                *data = rest;
                v |= ((b & 0x7f) as u64) << shift;
                if b & 0x80 == 0 {
                    return v;
                }
            }
            panic!("varint longer than 10 bytes")
        }
        let mut out = Vec::new();
        while !data.is_empty() {
            let key = varint(&mut data);
            let value = match key & 7 {
                0 => Value::Varint(varint(&mut data)),
                2 => {
                    let n = varint(&mut data) as usize;
                    let (head, rest) = data.split_at(n);
                    data = rest;
                    Value::Bytes(head)
                }
                5 => {
                    let (head, rest) = data.split_at(4);
                    data = rest;
                    Value::Fixed32(head.try_into().unwrap())
                }
                t => panic!("unexpected wire type {t}"),
            };
            out.push(((key >> 3) as u32, value));
        }
        out
    }

    fn str_of(b: &[u8]) -> String {
        String::from_utf8(b.to_vec()).unwrap()
    }

    #[derive(Debug, Default)]
    struct Node {
        inputs: Vec<String>,
        output: String,
        op: String,
        ints: HashMap<String, u64>,
        floats: HashMap<String, f32>,
    }

    #[derive(Debug, Default)]
    struct Model {
        ir_version: u64,
        producer: String,
        opsets: Vec<(String, u64)>,
        nodes: Vec<Node>,
        /// name → (dims, data_type, values)
        initializers: HashMap<String, (Vec<u64>, u64, Vec<f32>)>,
        inputs: Vec<(String, u64, Vec<String>)>,
        outputs: Vec<(String, u64, Vec<String>)>,
        metadata: Vec<(String, String)>,
    }

    /// `ValueInfoProto` → (name, elem_type, dims as `dim_value` or `dim_param` strings).
    fn value_info(b: &[u8]) -> (String, u64, Vec<String>) {
        let (mut name, mut elem, mut dims) = (String::new(), 0, Vec::new());
        for (f, v) in fields(b) {
            match (f, v) {
                (1, Value::Bytes(s)) => name = str_of(s),
                (2, Value::Bytes(ty)) => {
                    let [(1, Value::Bytes(tensor))] = fields(ty)[..] else {
                        panic!("not a tensor type")
                    };
                    for (f, v) in fields(tensor) {
                        match (f, v) {
                            (1, Value::Varint(e)) => elem = e,
                            (2, Value::Bytes(shape)) => {
                                for (f, dim) in fields(shape) {
                                    let (1, Value::Bytes(dim)) = (f, dim) else {
                                        panic!("bad shape")
                                    };
                                    dims.push(match fields(dim)[..] {
                                        [(1, Value::Varint(n))] => n.to_string(),
                                        [(2, Value::Bytes(p))] => str_of(p),
                                        _ => panic!("bad dim"),
                                    });
                                }
                            }
                            _ => panic!("unexpected tensor type field {f}"),
                        }
                    }
                }
                _ => panic!("unexpected value info field {f}"),
            }
        }
        (name, elem, dims)
    }

    fn decode(bytes: &[u8]) -> Model {
        let mut m = Model::default();
        for (f, v) in fields(bytes) {
            match (f, v) {
                (1, Value::Varint(v)) => m.ir_version = v,
                (2, Value::Bytes(s)) => m.producer = str_of(s),
                (3, Value::Bytes(_)) => {}
                (8, Value::Bytes(op)) => {
                    let [(1, Value::Bytes(d)), (2, Value::Varint(v))] = fields(op)[..] else {
                        panic!("bad opset")
                    };
                    m.opsets.push((str_of(d), v));
                }
                (14, Value::Bytes(e)) => {
                    let [(1, Value::Bytes(k)), (2, Value::Bytes(v))] = fields(e)[..] else {
                        panic!("bad metadata entry")
                    };
                    m.metadata.push((str_of(k), str_of(v)));
                }
                (7, Value::Bytes(g)) => {
                    for (f, v) in fields(g) {
                        match (f, v) {
                            (1, Value::Bytes(n)) => m.nodes.push(decode_node(n)),
                            (5, Value::Bytes(t)) => {
                                let (mut dims, mut ty, mut name, mut raw) =
                                    (Vec::new(), 0, String::new(), Vec::new());
                                for (f, v) in fields(t) {
                                    match (f, v) {
                                        (1, Value::Varint(d)) => dims.push(d),
                                        (2, Value::Varint(t)) => ty = t,
                                        (8, Value::Bytes(s)) => name = str_of(s),
                                        (9, Value::Bytes(r)) => raw = r.to_vec(),
                                        _ => panic!("unexpected tensor field {f}"),
                                    }
                                }
                                let values = raw
                                    .chunks_exact(4)
                                    .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                                    .collect();
                                m.initializers.insert(name, (dims, ty, values));
                            }
                            (11, Value::Bytes(i)) => m.inputs.push(value_info(i)),
                            (12, Value::Bytes(o)) => m.outputs.push(value_info(o)),
                            (2 | 10, Value::Bytes(_)) => {}
                            _ => panic!("unexpected graph field {f}"),
                        }
                    }
                }
                _ => panic!("unexpected model field {f}"),
            }
        }
        m
    }

    fn decode_node(b: &[u8]) -> Node {
        let mut n = Node::default();
        for (f, v) in fields(b) {
            match (f, v) {
                (1, Value::Bytes(s)) => n.inputs.push(str_of(s)),
                (2, Value::Bytes(s)) => n.output = str_of(s),
                (3, Value::Bytes(_)) => {}
                (4, Value::Bytes(s)) => n.op = str_of(s),
                (5, Value::Bytes(a)) => {
                    let (mut name, mut f32v, mut int, mut ty) = (String::new(), None, None, 0);
                    for (f, v) in fields(a) {
                        match (f, v) {
                            (1, Value::Bytes(s)) => name = str_of(s),
                            (2, Value::Fixed32(x)) => f32v = Some(f32::from_le_bytes(x)),
                            (3, Value::Varint(i)) => int = Some(i),
                            (20, Value::Varint(t)) => ty = t,
                            _ => panic!("unexpected attribute field {f}"),
                        }
                    }
                    match (ty, f32v, int) {
                        (ATTR_FLOAT, Some(x), None) => {
                            n.floats.insert(name, x);
                        }
                        (ATTR_INT, None, Some(i)) => {
                            n.ints.insert(name, i);
                        }
                        other => panic!("attribute {name}: {other:?}"),
                    }
                }
                _ => panic!("unexpected node field {f}"),
            }
        }
        n
    }

    /// Runs the decoded graph (`Gemm`, `Elu` only) on `n` rows of `obs`.
    fn run(m: &Model, obs: &[f32], n: usize) -> Vec<f32> {
        let mut values: HashMap<String, (Vec<f32>, usize)> = HashMap::new();
        values.insert(ONNX_INPUT.into(), (obs.to_vec(), obs.len() / n));
        for node in &m.nodes {
            let (x, cols) = values[&node.inputs[0]].clone();
            let y = match node.op.as_str() {
                "Gemm" => {
                    assert_eq!(node.ints.get("transB"), Some(&1));
                    assert!(!node.ints.contains_key("transA"));
                    let (wd, _, w) = &m.initializers[&node.inputs[1]];
                    let (_, _, b) = &m.initializers[&node.inputs[2]];
                    let (out, inp) = (wd[0] as usize, wd[1] as usize);
                    assert_eq!(inp, cols, "{}", node.inputs[1]);
                    let mut y = vec![0f32; n * out];
                    for r in 0..n {
                        for o in 0..out {
                            let mut acc = b[o];
                            for i in 0..inp {
                                acc += x[r * inp + i] * w[o * inp + i];
                            }
                            y[r * out + o] = acc;
                        }
                    }
                    (y, out)
                }
                "Elu" => {
                    assert_eq!(node.floats.get("alpha"), Some(&1.0));
                    let y = x
                        .iter()
                        .map(|&v| if v < 0.0 { v.exp_m1() } else { v })
                        .collect();
                    (y, cols)
                }
                op => panic!("unexpected op {op}"),
            };
            values.insert(node.output.clone(), y);
        }
        values.remove(ONNX_OUTPUT).unwrap().0
    }

    #[test]
    fn model_header_io_and_metadata() {
        let policy = policy();
        let m = decode(&policy.to_onnx().unwrap());
        assert_eq!(m.ir_version, 8);
        assert_eq!(m.producer, "l3p");
        assert_eq!(m.opsets, vec![(String::new(), 17)]);
        let dims = |w: usize| vec!["batch".to_string(), w.to_string()];
        assert_eq!(m.inputs, vec![("obs".into(), FLOAT, dims(50))]);
        assert_eq!(m.outputs, vec![("actions".into(), FLOAT, dims(12))]);

        let meta: HashMap<_, _> = m.metadata.iter().cloned().collect();
        assert_eq!(meta.len(), m.metadata.len(), "duplicate metadata keys");
        let cfg: ExportConfig = serde_json::from_str(&meta["l3p_export"]).unwrap();
        assert_eq!(cfg, policy.config);
        assert!(cfg.io.is_some(), "the controller contract travels along");
        let on_disk: ExportConfig = serde_json::from_slice(
            &std::fs::read(Path::new(EXPORT_DIR).join("policy.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(cfg, on_disk, "same config as policy.json");
        assert_eq!(meta["format"], "l3p-export-v1");
        assert_eq!(meta["robot"], "a1");
        assert_eq!(meta["arch"], cfg.arch);
        assert_eq!(meta["obs_dim"], "50");
        assert_eq!(meta["action_dim"], "12");
        assert_eq!(
            meta["action_scale"].parse::<f32>().unwrap(),
            cfg.action_scale
        );
        let std: Vec<f32> = serde_json::from_str(&meta["action_std"]).unwrap();
        assert_eq!(std, policy.std());
    }

    #[test]
    fn nodes_follow_the_layers_and_initializers_hold_the_file_weights() {
        let policy = policy();
        let m = decode(&policy.to_onnx().unwrap());
        let mut expected_ops = Vec::new();
        for l in &policy.config.layers {
            expected_ops.push("Gemm");
            if l.activation == "elu" {
                expected_ops.push("Elu");
            }
        }
        let ops: Vec<&str> = m.nodes.iter().map(|n| n.op.as_str()).collect();
        assert_eq!(ops, expected_ops);
        // A chain: each node reads the previous one's output; the last writes `actions`.
        let mut x = "obs".to_string();
        for n in &m.nodes {
            assert_eq!(n.inputs[0], x);
            x = n.output.clone();
        }
        assert_eq!(x, "actions");
        assert_eq!(m.nodes.iter().filter(|n| n.output == "actions").count(), 1);

        let bytes = std::fs::read(Path::new(EXPORT_DIR).join("policy.safetensors")).unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        assert_eq!(m.initializers.len(), 2 * policy.config.layers.len());
        for l in &policy.config.layers {
            for (suffix, dims) in [
                ("weight", vec![l.output as u64, l.input as u64]),
                ("bias", vec![l.output as u64]),
            ] {
                let name = format!("{}.{suffix}", l.name);
                let (d, ty, values) = &m.initializers[&name];
                assert_eq!((d, *ty), (&dims, FLOAT), "{name}");
                let file: Vec<f32> = st
                    .tensor(&name)
                    .unwrap()
                    .data()
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                    .collect();
                assert_eq!(values, &file, "{name} holds the file's weights");
            }
        }
    }

    #[test]
    fn the_graph_computes_the_deploy_actions() {
        let policy = policy();
        let m = decode(&policy.to_onnx().unwrap());
        let n = 9;
        let obs: Vec<f32> = (0..n * 50)
            .map(|i| ((i * 37 % 101) as f32 / 101.0 - 0.5) * (1.0 + (i % 7) as f32))
            .collect();
        let expected = policy.act(&obs).unwrap();
        let got = run(&m, &obs, n);
        assert_eq!(got.len(), expected.len());
        for (g, e) in got.iter().zip(&expected) {
            assert!((g - e).abs() <= 1e-6 * (1.0 + e.abs()), "{g} vs {e}");
        }
    }

    #[test]
    fn bytes_are_deterministic() {
        let a = policy().to_onnx().unwrap();
        let b = policy().to_onnx().unwrap();
        assert_eq!(a, b);
        // Another config gives other bytes (it travels in the metadata).
        let mut other = policy();
        other.config.robot = "go1".into();
        assert_ne!(other.to_onnx().unwrap(), a);
    }
}
