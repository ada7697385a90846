//! [`PolicyRunner`]: an ONNX policy and its contract as a [`Controller`]. It builds the
//! observation from what a robot reports (scan, pose, velocity, goal) exactly as the contract
//! says, runs the network with tract, carries recurrent state, and returns the command
//! clipped to the contract's limits. Anything wrong in what it is given stops the robot
//! (zero command) and is reported by [`PolicyRunner::fault`].

use crate::contract::{ActionContract, CONTRACT_KEY, PolicyContract};
use crate::scan::{ScanAdapter, ScanError};
use rlnav_sim::observation::{ObservationBuilder, ObservationInputs};
use rlnav_sim::{Controller, RobotObservation, Twist};
use std::path::Path;
use tract_onnx::pb;
use tract_onnx::prelude::*;

/// Why a policy could not be loaded or run.
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// The file could not be read.
    #[error("{file}: cannot read: {error}")]
    Io {
        /// The file.
        file: String,
        /// What the OS said (in the message, not chained, so that it is said once).
        error: std::io::Error,
    },
    /// Not an ONNX model tract can load.
    #[error("{file}: not a loadable ONNX model: {message}")]
    Model {
        /// The file.
        file: String,
        /// tract's message.
        message: String,
    },
    /// No contract in the file and none given.
    #[error(
        "{file}: no `{CONTRACT_KEY}` in the model's metadata_props (not exported by rlnav?): give a side contract \
         (--contract FILE, see contracts/)"
    )]
    NoContract {
        /// The file.
        file: String,
    },
    /// A contract that is not valid.
    #[error(transparent)]
    Contract(#[from] rlnav_sim::ConfigError),
    /// The graph does not match the contract.
    #[error("{file}: the model does not match its contract: {message}")]
    Mismatch {
        /// The file.
        file: String,
        /// What differs.
        message: String,
    },
    /// Inference failed.
    #[error("inference failed: {0}")]
    Inference(String),
    /// The observation could not be built.
    #[error(transparent)]
    Scan(#[from] ScanError),
    /// The policy's linear action is a share of the robot's top speed, and none was given.
    #[error(
        "{file}: its linear action is a fraction of the robot's top speed ({min}–{max}), and the robot's top \
         speed was not given (the ROS 2 node's `max_linear`)"
    )]
    NoTopSpeed {
        /// The file.
        file: String,
        /// The contract's linear range, fractions of the top speed.
        min: f32,
        /// Its upper end.
        max: f32,
    },
}

/// What one inference returns.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyOutput {
    /// Action mean (before scaling and clipping).
    pub mu: [f32; 2],
    /// The value estimate, when the graph has a `value` output.
    pub value: Option<f32>,
}

type Plan = std::sync::Arc<TypedRunnableModel>;

/// A loaded policy, ready to drive.
pub struct PolicyRunner {
    contract: PolicyContract,
    source: String,
    plan: Plan,
    /// Graph input positions: the observation, then each recurrent state in contract order.
    obs_input: usize,
    state_inputs: Vec<usize>,
    n_inputs: usize,
    mu_output: usize,
    value_output: Option<usize>,
    state_outputs: Vec<usize>,
    state: Vec<Tensor>,
    obs: Vec<f32>,
    scan: Vec<f32>,
    /// The same builder the simulator writes training observations with; it keeps the
    /// history terms' past.
    observer: ObservationBuilder,
    adapter: Option<ScanAdapter>,
    last: Twist,
    fault: Option<String>,
    /// The contract's action in m/s: `None` while a relative one waits for the robot's top
    /// speed ([`Self::set_top_speed`]).
    action: Option<ActionContract>,
    /// The plan being followed and the segment the robot's projection lay on last (policies
    /// trained on plans); a new plan starts from its beginning.
    nav_plan: Option<std::sync::Arc<[rlnav_sim::Vec2]>>,
    plan_progress: usize,
    /// The `plan_ahead` observation term's points (robot frame), preallocated.
    ahead: Vec<rlnav_sim::Vec2>,
    name: String,
}

impl std::fmt::Debug for PolicyRunner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PolicyRunner").field("source", &self.source).field("contract", &self.contract).finish()
    }
}

/// The action in m/s for a robot of `top_speed` (m/s): `None` for a range in shares of the top
/// speed while none is known or it is not a positive number.
fn resolved(action: &ActionContract, top_speed: Option<f32>) -> Option<ActionContract> {
    match top_speed {
        Some(v) if v.is_finite() && v > 0.0 => Some(action.for_top_speed(v)),
        _ => (!action.linear_relative).then(|| action.clone()),
    }
}

/// The graph's input and output names, in order.
pub fn graph_io(proto: &pb::ModelProto) -> (Vec<String>, Vec<String>) {
    let g = proto.graph.as_ref();
    let initialised: std::collections::HashSet<&str> =
        g.map(|g| g.initializer.iter().map(|t| t.name.as_str()).collect()).unwrap_or_default();
    let inputs = g
        .map(|g| g.input.iter().map(|i| i.name.clone()).filter(|n| !initialised.contains(n.as_str())).collect())
        .unwrap_or_default();
    let outputs = g.map(|g| g.output.iter().map(|o| o.name.clone()).collect()).unwrap_or_default();
    (inputs, outputs)
}

/// Static dimensions of a graph input (`None` for symbolic ones).
pub fn input_dims(proto: &pb::ModelProto, name: &str) -> Option<Vec<Option<i64>>> {
    use pb::tensor_shape_proto::dimension::Value;
    let vi = proto.graph.as_ref()?.input.iter().find(|i| i.name == name)?;
    let pb::type_proto::Value::TensorType(t) = vi.r#type.as_ref()?.value.as_ref()?;
    Some(
        t.shape
            .as_ref()?
            .dim
            .iter()
            .map(|d| match &d.value {
                Some(Value::DimValue(v)) => Some(*v),
                _ => None,
            })
            .collect(),
    )
}

/// Reads an ONNX file's protobuf.
pub fn read_model(path: &Path) -> Result<pb::ModelProto, PolicyError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| PolicyError::Io { file: file.clone(), error })?;
    parse_model(&file, &bytes)
}

/// Parses an ONNX model held in memory (`file` names it in errors).
fn parse_model(file: &str, bytes: &[u8]) -> Result<pb::ModelProto, PolicyError> {
    tract_onnx::onnx()
        .proto_model_for_read(&mut &bytes[..])
        .map_err(|e| PolicyError::Model { file: file.to_string(), message: format!("{e:#}") })
}

/// The contract embedded in a model, if any.
pub fn embedded_contract(proto: &pb::ModelProto, file: &str) -> Result<Option<PolicyContract>, PolicyError> {
    match proto.metadata_props.iter().find(|p| p.key == CONTRACT_KEY) {
        Some(p) => Ok(Some(PolicyContract::from_yaml(&format!("{file} (metadata {CONTRACT_KEY})"), &p.value)?)),
        None => Ok(None),
    }
}

impl PolicyRunner {
    /// Loads `model` with its embedded contract, or with the side contract `contract`.
    pub fn load(model: &Path, contract: Option<&Path>) -> Result<Self, PolicyError> {
        let file = model.display().to_string();
        let proto = read_model(model)?;
        let contract = match contract {
            Some(p) => PolicyContract::from_file(p)?,
            None => embedded_contract(&proto, &file)?.ok_or(PolicyError::NoContract { file: file.clone() })?,
        };
        Self::from_proto(&file, &proto, contract)
    }

    /// Loads a model held in memory with its embedded contract (a policy built into a
    /// binary); `name` stands for its file in errors.
    pub fn from_bytes(name: &str, bytes: &[u8]) -> Result<Self, PolicyError> {
        let proto = parse_model(name, bytes)?;
        let contract = embedded_contract(&proto, name)?.ok_or(PolicyError::NoContract { file: name.to_string() })?;
        Self::from_proto(name, &proto, contract)
    }

    /// Builds a runner from a parsed model and a contract.
    pub fn from_proto(file: &str, proto: &pb::ModelProto, contract: PolicyContract) -> Result<Self, PolicyError> {
        let mismatch = |message: String| PolicyError::Mismatch { file: file.to_string(), message };
        let (inputs, outputs) = graph_io(proto);
        let io = &contract.io;
        let position = |names: &[String], n: &str, what: &str| {
            names
                .iter()
                .position(|x| x == n)
                .ok_or_else(|| mismatch(format!("no {what} `{n}` (the graph has {names:?})")))
        };
        let obs_input = position(&inputs, &io.obs, "input")?;
        let mu_output = position(&outputs, &io.mu, "output")?;
        let value_output = outputs.iter().position(|o| o == "value");
        let mut state_inputs = Vec::new();
        let mut state_outputs = Vec::new();
        for s in &io.recurrent {
            state_inputs.push(position(&inputs, &s.input, "state input")?);
            state_outputs.push(position(&outputs, &s.output, "state output")?);
        }
        if inputs.len() != 1 + state_inputs.len() {
            return Err(mismatch(format!(
                "the graph has inputs {inputs:?}; the contract knows only `{}` and its {} recurrent state(s)",
                io.obs,
                io.recurrent.len()
            )));
        }
        let n = contract.obs_dim();
        if let Some(dims) = input_dims(proto, &io.obs) {
            if dims.len() != 2 || dims[1].is_some_and(|d| d != n as i64) {
                return Err(mismatch(format!(
                    "input `{}` has shape {dims:?}; the contract's observation has {n} values ({} terms)",
                    io.obs,
                    contract.observation.0.len()
                )));
            }
        }
        for s in &io.recurrent {
            if let Some(dims) = input_dims(proto, &s.input) {
                let ok = dims.len() == s.shape.len()
                    && dims.iter().zip(&s.shape).all(|(d, want)| d.is_none_or(|d| d == *want as i64));
                if !ok {
                    return Err(mismatch(format!(
                        "state `{}` has shape {dims:?}, the contract says {:?}",
                        s.input, s.shape
                    )));
                }
            }
        }
        let tract_err = |e: TractError| mismatch(format!("{e:#}"));
        let mut model = tract_onnx::onnx().model_for_proto_model(proto).map_err(tract_err)?;
        model = model.with_input_fact(obs_input, f32::fact([1, n]).into()).map_err(tract_err)?;
        for (s, i) in io.recurrent.iter().zip(&state_inputs) {
            model = model.with_input_fact(*i, f32::fact(s.shape.clone()).into()).map_err(tract_err)?;
        }
        let plan = model.into_optimized().and_then(|m| m.into_runnable()).map_err(tract_err)?;
        let state = io.recurrent.iter().map(|s| Tensor::zero::<f32>(&s.shape).expect("shape")).collect();
        let name = format!(
            "rl:{}",
            Path::new(file).file_stem().map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned())
        );
        let mut runner = Self {
            source: file.to_string(),
            plan,
            obs_input,
            state_inputs,
            n_inputs: inputs.len(),
            mu_output,
            value_output,
            state_outputs,
            state,
            obs: vec![0.0; n],
            scan: vec![0.0; contract.scan.beams],
            observer: ObservationBuilder::new(&contract.observation),
            adapter: None,
            last: Twist::default(),
            fault: None,
            action: resolved(&contract.action, None),
            nav_plan: None,
            plan_progress: 0,
            ahead: Vec::new(),
            name,
            contract,
        };
        // One inference now, so that a graph tract cannot run fails at load, not at the first step.
        runner.infer(&vec![0.0; n]).map_err(|e| mismatch(e.to_string()))?;
        runner.reset_state();
        Ok(runner)
    }

    /// The contract.
    pub fn contract(&self) -> &PolicyContract {
        &self.contract
    }

    /// Where the model came from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Whether scans of a lidar like `spec` (as a robot reports them: in its sensor frame, mount
    /// yaw applied) can feed this policy; call it when the robot is known, before driving.
    pub fn check_lidar(&self, spec: &rlnav_sim::LidarSpec) -> Result<(), PolicyError> {
        let scan = rlnav_sim::LaserScan { ranges: vec![1.0; spec.beams], ..rlnav_sim::LaserScan::for_spec(spec) };
        ScanAdapter::new(&self.contract.scan, &scan, spec.mount.yaw)?;
        Ok(())
    }

    /// Tells the runner the robot's top speed (m/s), which a policy whose linear action is a
    /// fraction of it needs; it changes nothing for one in m/s. A speed that is not a
    /// positive number leaves such a policy without one: it stops the robot and says so.
    pub fn set_top_speed(&mut self, top_speed: f32) {
        self.action = resolved(&self.contract.action, Some(top_speed));
    }

    /// Whether the policy needs the robot's top speed ([`Self::set_top_speed`]) and has none.
    pub fn needs_top_speed(&self) -> bool {
        self.action.is_none()
    }

    /// [`PolicyError::NoTopSpeed`] while the policy needs the robot's top speed and has none.
    pub fn check_top_speed(&self) -> Result<(), PolicyError> {
        if self.action.is_some() {
            return Ok(());
        }
        let [min, max] = self.contract.action.linear;
        Err(PolicyError::NoTopSpeed { file: self.source.clone(), min, max })
    }

    /// Why the last [`Controller::act`] stopped the robot, if it did.
    pub fn fault(&self) -> Option<&str> {
        self.fault.as_deref()
    }

    fn reset_state(&mut self) {
        for (t, s) in self.state.iter_mut().zip(&self.contract.io.recurrent) {
            *t = Tensor::zero::<f32>(&s.shape).expect("shape");
        }
        self.observer.reset();
        self.last = Twist::default();
        self.nav_plan = None;
        self.plan_progress = 0;
    }

    /// Runs the network on a raw observation (length [`PolicyContract::obs_dim`]), advancing
    /// the recurrent state.
    pub fn infer(&mut self, obs: &[f32]) -> Result<PolicyOutput, PolicyError> {
        let n = self.contract.obs_dim();
        if obs.len() != n {
            return Err(PolicyError::Inference(format!("observation of {} values, the contract says {n}", obs.len())));
        }
        let err = |e: TractError| PolicyError::Inference(format!("{e:#}"));
        let mut inputs: Vec<Option<TValue>> = vec![None; self.n_inputs];
        inputs[self.obs_input] = Some(Tensor::from_shape(&[1, n], obs).map_err(err)?.into());
        for (i, t) in self.state_inputs.iter().zip(&self.state) {
            inputs[*i] = Some(t.clone().into());
        }
        let inputs: TVec<TValue> = inputs.into_iter().map(|t| t.expect("every input set")).collect();
        let out = self.plan.run(inputs).map_err(err)?;
        let mu_view = out[self.mu_output].to_plain_array_view::<f32>().map_err(err)?;
        let mut mu_iter = mu_view.iter().copied();
        let (Some(m0), Some(m1)) = (mu_iter.next(), mu_iter.next()) else {
            return Err(PolicyError::Inference(format!("`{}` has fewer than 2 values", self.contract.io.mu)));
        };
        let mu = [m0, m1];
        let value = self
            .value_output
            .and_then(|i| out[i].to_plain_array_view::<f32>().ok().and_then(|v| v.iter().next().copied()));
        for (k, i) in self.state_outputs.iter().enumerate() {
            self.state[k] = out[*i].clone().into_tensor();
        }
        Ok(PolicyOutput { mu, value })
    }

    /// Builds the contract's observation vector from what the robot reports; the command
    /// given last is this runner's own. History terms show the observations of the steps
    /// acted on since the last reset; building again before acting replaces the current step.
    pub fn build_observation(&mut self, o: &RobotObservation) -> Result<&[f32], PolicyError> {
        let mount_yaw = o.scan_mount.yaw;
        if !self.adapter.as_ref().is_some_and(|a| a.fits(&o.scan, mount_yaw)) {
            self.adapter = Some(ScanAdapter::new(&self.contract.scan, &o.scan, mount_yaw)?);
        }
        self.adapter.as_ref().expect("set above").adapt(&o.scan, &mut self.scan)?;
        // A policy trained on plans steers to the point a lookahead ahead on the robot's plan.
        let target = match &self.contract.plan {
            Some(p) if !o.plan.is_empty() => {
                if !self.nav_plan.as_ref().is_some_and(|q| std::sync::Arc::ptr_eq(q, &o.plan)) {
                    self.nav_plan = Some(o.plan.clone());
                    self.plan_progress = 0;
                }
                rlnav_sim::plan::plan_subgoal(&o.plan, &mut self.plan_progress, o.pose.position(), p.lookahead)
            }
            _ => o.goal,
        };
        let (goal_distance, goal_bearing) = o.pose.polar_of(target);
        if let Some((points, spacing)) = self.contract.observation.plan_ahead() {
            // The plan the policy follows (as in training), or none: the line to the goal.
            let plan: &[rlnav_sim::Vec2] = if self.contract.plan.is_some() { &o.plan } else { &[] };
            self.ahead.resize(points, rlnav_sim::Vec2::ZERO);
            rlnav_sim::plan::points_ahead(plan, self.plan_progress, o.goal, &o.pose, spacing, &mut self.ahead);
        }
        let spec = self.contract.scan.lidar_spec();
        let inputs = ObservationInputs {
            ranges: &self.scan,
            angle_increment: spec.angle_increment(),
            angle_min: spec.angle_min,
            // The adapted scan is measured from the lidar, in bearings of `base_link`.
            pose: o.pose.compose(&rlnav_sim::Pose2::new(o.scan_mount.x, o.scan_mount.y, 0.0)),
            goal_distance,
            goal_bearing,
            last_command: self.last,
            velocity: o.velocity,
            lateral_velocity: o.lateral_velocity,
            plan_ahead: &self.ahead,
        };
        self.observer.write(&inputs, &mut self.obs, || 0.0);
        if let Some(i) = self.obs.iter().position(|x| !x.is_finite()) {
            return Err(PolicyError::Inference(format!(
                "observation value {i} is not finite (pose, goal or velocity)"
            )));
        }
        Ok(&self.obs)
    }

    /// One control step: observation, inference, command; errors instead of stopping.
    pub fn try_act(&mut self, o: &RobotObservation) -> Result<Twist, PolicyError> {
        self.check_top_speed()?;
        self.build_observation(o)?;
        // This step's observation joins the history whatever the network makes of it: the
        // robot was there and saw it.
        self.observer.commit();
        let obs = std::mem::take(&mut self.obs);
        let out = self.infer(&obs);
        self.obs = obs;
        let mu = out?.mu;
        let cmd = self.action.as_ref().map_or_else(Twist::default, |a| a.to_twist(mu));
        self.last = cmd;
        Ok(cmd)
    }
}

impl Controller for PolicyRunner {
    fn act(&mut self, obs: &RobotObservation) -> Twist {
        match self.try_act(obs) {
            Ok(t) => {
                self.fault = None;
                t
            }
            Err(e) => {
                // Garbage in stops the robot; the reason stays readable.
                self.fault = Some(e.to_string());
                self.last = Twist::default();
                Twist::default()
            }
        }
    }

    fn reset(&mut self) {
        self.reset_state();
        self.fault = None;
    }

    fn name(&self) -> &str {
        &self.name
    }
}
