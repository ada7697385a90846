//! ONNX export of an actor-critic with its observation normalisation inside the graph and the
//! policy contract in `metadata_props`.
//!
//! The protobuf types are the ones `tract-onnx` generates with prost (`tract_onnx::pb`); the
//! graph follows rl_games' exports so that tools written for the article's files keep working:
//! input `obs` `[batch, n]`, outputs `mu`, `log_std`, `value`; an LSTM policy adds the inputs
//! `out_state.1` (h) and `hidden_state.1` (c), `[1, batch, units]`, and the outputs
//! `out_state` and `hidden_state`. Opset 14.

use crate::contract::{CONTRACT_KEY, GraphIo, PolicyContract, RecurrentState};
use crate::network::{ActivationKind, ActorCritic};
use crate::normalizer::RunningMeanStd;
use burn::nn::Linear;
use burn::prelude::*;
use prost::Message;
use tract_onnx::pb;

/// Opset the exporter writes.
pub const OPSET: i64 = 14;

/// Why a network could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The normaliser and the network disagree on the observation length, or the contract does.
    #[error("observation length mismatch: {0}")]
    Shape(String),
    /// The network uses something the exporter does not write.
    #[error("cannot export: {0}")]
    Unsupported(String),
}

fn floats<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec::<f32>().expect("f32 tensor data")
}

fn linear_parts(l: &Linear) -> (Vec<f32>, [usize; 2], Vec<f32>) {
    let w = l.weight.val();
    let [i, o] = w.dims();
    let b = l.bias.as_ref().map(|b| floats(b.val())).unwrap_or_else(|| vec![0.0; o]);
    (floats(w), [i, o], b)
}

/// Incrementally built graph.
struct Graph {
    nodes: Vec<pb::NodeProto>,
    inits: Vec<pb::TensorProto>,
    count: usize,
}

impl Graph {
    fn tensor(&mut self, name: &str, dims: &[usize], data: Vec<f32>) -> String {
        self.inits.push(pb::TensorProto {
            name: name.to_string(),
            dims: dims.iter().map(|d| *d as i64).collect(),
            data_type: pb::tensor_proto::DataType::Float as i32,
            float_data: data,
            ..Default::default()
        });
        name.to_string()
    }

    fn ints(&mut self, name: &str, data: &[i64]) -> String {
        self.inits.push(pb::TensorProto {
            name: name.to_string(),
            dims: vec![data.len() as i64],
            data_type: pb::tensor_proto::DataType::Int64 as i32,
            int64_data: data.to_vec(),
            ..Default::default()
        });
        name.to_string()
    }

    /// Adds a node; `out` names its (first) output, or a fresh name is made.
    fn node(&mut self, op: &str, inputs: &[&str], outputs: &[&str], attrs: Vec<pb::AttributeProto>) -> String {
        self.count += 1;
        let outs: Vec<String> = if outputs.is_empty() {
            vec![format!("{}_{}", op.to_lowercase(), self.count)]
        } else {
            outputs.iter().map(|s| s.to_string()).collect()
        };
        self.nodes.push(pb::NodeProto {
            name: format!("{op}_{}", self.count),
            op_type: op.to_string(),
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: outs.clone(),
            attribute: attrs,
            ..Default::default()
        });
        outs[0].clone()
    }

    fn gemm(&mut self, x: &str, l: &Linear, prefix: &str, out: Option<&str>) -> String {
        let (w, dims, b) = linear_parts(l);
        self.gemm_raw(x, w, dims, b, prefix, out)
    }

    /// `x · w + b` with `w` `[inputs, outputs]`, row-major.
    fn gemm_raw(
        &mut self,
        x: &str,
        w: Vec<f32>,
        dims: [usize; 2],
        b: Vec<f32>,
        prefix: &str,
        out: Option<&str>,
    ) -> String {
        let w = self.tensor(&format!("{prefix}.weight"), &dims, w);
        let b = self.tensor(&format!("{prefix}.bias"), &[dims[1]], b);
        self.node("Gemm", &[x, &w, &b], out.as_slice(), Vec::new())
    }

    /// The observation normaliser in front of the network: `clip(obs * scale + shift)`, the
    /// same arithmetic as [`RunningMeanStd::normalize`].
    fn normalizer(&mut self, scale: Vec<f32>, shift: Vec<f32>, clip: f32) -> String {
        let n = scale.len();
        let scale = self.tensor("obs_norm.scale", &[n], scale);
        let shift = self.tensor("obs_norm.shift", &[n], shift);
        let lo = self.tensor("obs_norm.clip_min", &[], vec![-clip]);
        let hi = self.tensor("obs_norm.clip_max", &[], vec![clip]);
        let x = self.node("Mul", &["obs", &scale], &[], Vec::new());
        let x = self.node("Add", &[&x, &shift], &[], Vec::new());
        self.node("Clip", &[&x, &lo, &hi], &[], Vec::new())
    }

    /// The finished model carrying `contract` in `metadata_props`.
    fn model(
        self,
        contract: &PolicyContract,
        inputs: Vec<pb::ValueInfoProto>,
        outputs: Vec<pb::ValueInfoProto>,
    ) -> pb::ModelProto {
        let meta = [
            (CONTRACT_KEY.to_string(), contract.to_yaml()),
            ("rlnav.version".into(), env!("CARGO_PKG_VERSION").into()),
            ("rlnav.robot".into(), contract.robot.clone()),
            ("rlnav.task".into(), contract.task.clone()),
            ("rlnav.obs_dim".into(), contract.obs_dim().to_string()),
        ];
        pb::ModelProto {
            ir_version: 8,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: OPSET }],
            producer_name: "rlnav".into(),
            producer_version: env!("CARGO_PKG_VERSION").into(),
            doc_string: format!("rlnav policy for {} ({})", contract.robot, contract.task),
            graph: Some(pb::GraphProto {
                name: "rlnav_policy".into(),
                node: self.nodes,
                initializer: self.inits,
                input: inputs,
                output: outputs,
                ..Default::default()
            }),
            metadata_props: meta.into_iter().map(|(key, value)| pb::StringStringEntryProto { key, value }).collect(),
            ..Default::default()
        }
    }

    fn activation(&mut self, x: &str, a: ActivationKind) -> String {
        match a {
            ActivationKind::Elu => self.node("Elu", &[x], &[], vec![attr_f("alpha", 1.0)]),
            ActivationKind::Relu => self.node("Relu", &[x], &[], Vec::new()),
            ActivationKind::Tanh => self.node("Tanh", &[x], &[], Vec::new()),
        }
    }

    fn trunk(&mut self, x: &str, layers: &[Linear], a: ActivationKind, prefix: &str) -> String {
        let mut h = x.to_string();
        for (i, l) in layers.iter().enumerate() {
            let g = self.gemm(&h, l, &format!("{prefix}.{i}"), None);
            h = self.activation(&g, a);
        }
        h
    }
}

fn attr_f(name: &str, f: f32) -> pb::AttributeProto {
    pb::AttributeProto {
        name: name.into(),
        r#type: pb::attribute_proto::AttributeType::Float as i32,
        f,
        ..Default::default()
    }
}

fn attr_i(name: &str, i: i64) -> pb::AttributeProto {
    pb::AttributeProto {
        name: name.into(),
        r#type: pb::attribute_proto::AttributeType::Int as i32,
        i,
        ..Default::default()
    }
}

fn value_info(name: &str, dims: &[Option<usize>]) -> pb::ValueInfoProto {
    use pb::tensor_shape_proto::{Dimension, dimension::Value};
    let dim = dims
        .iter()
        .map(|d| Dimension {
            denotation: String::new(),
            value: Some(match d {
                Some(n) => Value::DimValue(*n as i64),
                None => Value::DimParam("batch".into()),
            }),
        })
        .collect();
    pb::ValueInfoProto {
        name: name.into(),
        r#type: Some(pb::TypeProto {
            denotation: String::new(),
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: pb::tensor_proto::DataType::Float as i32,
                shape: Some(pb::TensorShapeProto { dim }),
            })),
        }),
        ..Default::default()
    }
}

/// The recurrent state names of rlnav's LSTM exports (rl_games' names: `out_state` is h,
/// `hidden_state` is c).
pub fn lstm_io(units: usize) -> GraphIo {
    GraphIo {
        obs: "obs".into(),
        mu: "mu".into(),
        recurrent: vec![
            RecurrentState { input: "out_state.1".into(), output: "out_state".into(), shape: vec![1, 1, units] },
            RecurrentState { input: "hidden_state.1".into(), output: "hidden_state".into(), shape: vec![1, 1, units] },
        ],
    }
}

/// Builds the ONNX model of `net` with `norm` in front, carrying `contract`.
pub fn export_model(
    net: &ActorCritic,
    norm: &RunningMeanStd,
    contract: &PolicyContract,
) -> Result<pb::ModelProto, ExportError> {
    let n = net.obs_dim;
    if norm.dim() != n || contract.obs_dim() != n {
        return Err(ExportError::Shape(format!(
            "network {n}, normaliser {}, contract {}",
            norm.dim(),
            contract.obs_dim()
        )));
    }
    let mut g = Graph { nodes: Vec::new(), inits: Vec::new(), count: 0 };
    let (scale, shift) = norm.affine();
    let mut features = g.normalizer(scale, shift, norm.clip);

    let mut inputs = vec![value_info("obs", &[None, Some(n)])];
    let mut outputs = Vec::new();
    let act = net.action_dim();
    if let Some(lstm) = &net.lstm {
        if lstm.forget_gate.is_none() || lstm.clip.is_some() || lstm.reverse {
            return Err(ExportError::Unsupported("an LSTM with coupled gates, cell clipping or reversed".into()));
        }
        let h = lstm.d_hidden;
        // ONNX gate order i, o, f, c; weights [gates * h, in] (burn's are [in, h]).
        let gates = [&lstm.input_gate, &lstm.output_gate, lstm.forget_gate.as_ref().expect("checked"), &lstm.cell_gate];
        let transpose = |w: Vec<f32>, [i, o]: [usize; 2]| {
            let mut t = vec![0.0; i * o];
            for r in 0..i {
                for c in 0..o {
                    t[c * i + r] = w[r * o + c];
                }
            }
            t
        };
        let (mut w, mut r, mut wb, mut rb) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for gate in gates {
            let (wi, di, bi) = linear_parts(&gate.input_transform);
            let (wh, dh, bh) = linear_parts(&gate.hidden_transform);
            w.extend(transpose(wi, di));
            r.extend(transpose(wh, dh));
            wb.extend(bi);
            rb.extend(bh);
        }
        wb.extend(rb);
        let w = g.tensor("lstm.W", &[1, 4 * h, n], w);
        let r = g.tensor("lstm.R", &[1, 4 * h, h], r);
        let b = g.tensor("lstm.B", &[1, 8 * h], wb);
        let axis0 = g.ints("axes_0", &[0]);
        let axes01 = g.ints("axes_0_1", &[0, 1]);
        let seq = g.node("Unsqueeze", &[&features, &axis0], &[], Vec::new());
        let y = g.node(
            "LSTM",
            &[&seq, &w, &r, &b, "", "out_state.1", "hidden_state.1"],
            &["lstm_y", "out_state", "hidden_state"],
            vec![attr_i("hidden_size", h as i64)],
        );
        features = g.node("Squeeze", &[&y, &axes01], &[], Vec::new());
        for name in ["out_state.1", "hidden_state.1"] {
            inputs.push(value_info(name, &[Some(1), None, Some(h)]));
        }
        let want = lstm_io(h);
        if contract.io.recurrent != want.recurrent {
            return Err(ExportError::Shape(format!("the contract's recurrent states must be {:?}", want.recurrent)));
        }
    } else if !contract.io.recurrent.is_empty() {
        return Err(ExportError::Shape("the contract names recurrent states for a feed-forward network".into()));
    }
    let a = g.trunk(&features, &net.actor, net.activation, "actor");
    g.gemm(&a, &net.mu, "mu", Some("mu"));
    // A privileged critic reads what no robot measures: the file has no value output then.
    if net.critic_extra == 0 {
        let c = if net.critic.is_empty() { a } else { g.trunk(&features, &net.critic, net.activation, "critic") };
        g.gemm(&c, &net.value, "value", Some("value"));
    }
    // log_std per row, as rl_games writes it: mu * 0 + sigma.
    let zero = g.tensor("zero", &[], vec![0.0]);
    let sigma = g.tensor("sigma", &[act], floats(net.log_std.val()));
    let z = g.node("Mul", &["mu", &zero], &[], Vec::new());
    g.node("Add", &[&z, &sigma], &["log_std"], Vec::new());
    outputs.push(value_info("mu", &[None, Some(act)]));
    outputs.push(value_info("log_std", &[None, Some(act)]));
    if net.critic_extra == 0 {
        outputs.push(value_info("value", &[None, Some(1)]));
    }
    if let Some(l) = &net.lstm {
        for name in ["out_state", "hidden_state"] {
            outputs.push(value_info(name, &[Some(1), None, Some(l.d_hidden)]));
        }
    }

    Ok(g.model(contract, inputs, outputs))
}

/// [`export_model`] encoded as ONNX bytes.
pub fn export_onnx(
    net: &ActorCritic,
    norm: &RunningMeanStd,
    contract: &PolicyContract,
) -> Result<Vec<u8>, ExportError> {
    Ok(export_model(net, norm, contract)?.encode_to_vec())
}

/// One dense layer of a network given as plain weights (from PyTorch, say):
/// `y = activation(x · weight + bias)`.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseLayer {
    /// Weights `[inputs, outputs]`, row-major (PyTorch's `Linear.weight` transposed).
    pub weight: Vec<f32>,
    /// Input width.
    pub inputs: usize,
    /// Output width.
    pub outputs: usize,
    /// Bias, one per output.
    pub bias: Vec<f32>,
    /// Nonlinearity after the layer (`None`: linear, as the last layer).
    pub activation: Option<ActivationKind>,
}

/// An observation normaliser as the affine map it is: `clip(obs * scale + shift, ±clip)`
/// (`scale = 1 / sqrt(var + ε)`, `shift = -mean * scale`).
#[derive(Clone, Debug, PartialEq)]
pub struct ObsAffine {
    /// Per-value scale.
    pub scale: Vec<f32>,
    /// Per-value shift.
    pub shift: Vec<f32>,
    /// Clip after normalising (`inf`: none).
    pub clip: f32,
}

impl ObsAffine {
    /// No normalisation.
    pub fn identity(n: usize) -> Self {
        Self { scale: vec![1.0; n], shift: vec![0.0; n], clip: f32::INFINITY }
    }
}

/// Builds the ONNX model of a feed-forward actor given as plain layers (the last one gives
/// the normalised action mean `mu`, two values), with `norm` in front, carrying `contract`:
/// input `obs` `[batch, n]`, output `mu` `[batch, 2]`. Every shape and value is checked:
/// the chain of widths, the contract's observation length, finite weights.
pub fn export_mlp(
    layers: &[DenseLayer],
    norm: &ObsAffine,
    contract: &PolicyContract,
) -> Result<pb::ModelProto, ExportError> {
    let n = contract.obs_dim();
    if !contract.io.recurrent.is_empty() {
        return Err(ExportError::Shape("the contract names recurrent states for a feed-forward network".into()));
    }
    let Some(last) = layers.last() else {
        return Err(ExportError::Shape("no layers".into()));
    };
    let mut width = n;
    for (i, l) in layers.iter().enumerate() {
        if l.inputs != width {
            return Err(ExportError::Shape(format!("layer {i} takes {} values, expected {width}", l.inputs)));
        }
        if l.weight.len() != l.inputs * l.outputs || l.bias.len() != l.outputs {
            return Err(ExportError::Shape(format!(
                "layer {i}: expected {}×{} weights and {} biases, got {} and {}",
                l.inputs,
                l.outputs,
                l.outputs,
                l.weight.len(),
                l.bias.len()
            )));
        }
        if !l.weight.iter().chain(&l.bias).all(|x| x.is_finite()) {
            return Err(ExportError::Shape(format!("layer {i}: expected finite weights")));
        }
        width = l.outputs;
    }
    if norm.scale.len() != n || norm.shift.len() != n {
        return Err(ExportError::Shape(format!(
            "the contract's observation has {n} values, the normaliser's scale {} and shift {}",
            norm.scale.len(),
            norm.shift.len()
        )));
    }
    if !(norm.scale.iter().chain(&norm.shift).all(|x| x.is_finite()) && norm.clip > 0.0) {
        return Err(ExportError::Shape("the normaliser: expected finite scale and shift and a positive clip".into()));
    }
    if last.outputs != 2 || last.activation.is_some() {
        return Err(ExportError::Shape(format!(
            "the last layer gives the action mean: 2 outputs and no activation, got {}{}",
            last.outputs,
            if last.activation.is_some() { " with an activation" } else { "" }
        )));
    }
    let mut g = Graph { nodes: Vec::new(), inits: Vec::new(), count: 0 };
    let mut h = g.normalizer(norm.scale.clone(), norm.shift.clone(), norm.clip);
    for (i, l) in layers.iter().enumerate() {
        let out = (i + 1 == layers.len()).then_some("mu");
        h = g.gemm_raw(&h, l.weight.clone(), [l.inputs, l.outputs], l.bias.clone(), &format!("actor.{i}"), out);
        if let Some(a) = l.activation {
            h = g.activation(&h, a);
        }
    }
    let io = &contract.io;
    if io.obs != "obs" || io.mu != "mu" {
        return Err(ExportError::Shape(format!(
            "the contract's graph names: expected obs and mu, got {} and {}",
            io.obs, io.mu
        )));
    }
    Ok(g.model(contract, vec![value_info("obs", &[None, Some(n)])], vec![value_info("mu", &[None, Some(2)])]))
}

/// [`export_mlp`] encoded as ONNX bytes.
pub fn export_mlp_onnx(
    layers: &[DenseLayer],
    norm: &ObsAffine,
    contract: &PolicyContract,
) -> Result<Vec<u8>, ExportError> {
    Ok(export_mlp(layers, norm, contract)?.encode_to_vec())
}

/// A model of the contract's shape whose action mean echoes two observation values:
/// `mu = [obs[reads[0]], obs[reads[1]]]`. Run through a deployment with `scaling: direct` and
/// wide action limits, its commands show which values sit where, so that a side contract (or
/// the code that feeds it) can be checked against a layout value by value. Each recurrent
/// state's output is its input plus one (a step count that the runner carries). No contract
/// in `metadata_props`: it stands for a foreign model.
pub fn echo_model(obs_dim: usize, reads: [usize; 2], io: &GraphIo) -> Result<pb::ModelProto, ExportError> {
    if let Some(r) = reads.iter().find(|r| **r >= obs_dim) {
        return Err(ExportError::Shape(format!("index {r} read from an observation of {obs_dim} values")));
    }
    let mut g = Graph { nodes: Vec::new(), inits: Vec::new(), count: 0 };
    let mut w = vec![0.0; obs_dim * 2];
    w[reads[0] * 2] = 1.0;
    w[reads[1] * 2 + 1] = 1.0;
    let w = g.tensor("echo.weight", &[obs_dim, 2], w);
    let b = g.tensor("echo.bias", &[2], vec![0.0; 2]);
    g.node("Gemm", &[&io.obs, &w, &b], &[&io.mu], Vec::new());
    let mut inputs = vec![value_info(&io.obs, &[None, Some(obs_dim)])];
    let mut outputs = vec![value_info(&io.mu, &[None, Some(2)])];
    let one = g.tensor("one", &[], vec![1.0]);
    for s in &io.recurrent {
        let dims: Vec<Option<usize>> = s.shape.iter().map(|d| Some(*d)).collect();
        g.node("Add", &[&s.input, &one], &[&s.output], Vec::new());
        inputs.push(value_info(&s.input, &dims));
        outputs.push(value_info(&s.output, &dims));
    }
    Ok(pb::ModelProto {
        ir_version: 8,
        opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: OPSET }],
        producer_name: "rlnav echo".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        graph: Some(pb::GraphProto {
            name: "echo".into(),
            node: g.nodes,
            initializer: g.inits,
            input: inputs,
            output: outputs,
            ..Default::default()
        }),
        ..Default::default()
    })
}
