//! ONNX export and tract inference: the exported MLP and LSTM compute what the burn networks
//! compute (normalisation included), the contract survives the trip through
//! `metadata_props`, and files that do not fit their contract fail at load.
//!
//! With `RLNAV_ORT_PYTHON` set to a Python that has `onnx` and `onnxruntime` (CI sets it up),
//! the same files are also checked with `onnx.checker` and run by ONNX Runtime.

use burn::prelude::*;
use prost::Message;
use rand::{RngExt, SeedableRng};
use rlnav_policy::contract::{ActionContract, ActionScaling, CONTRACT_FORMAT, GraphIo, PolicyContract, ScanContract};
use rlnav_policy::export::{DenseLayer, ObsAffine, export_mlp, export_model, lstm_io};
use rlnav_policy::{ActivationKind, ActorCritic, NetworkConfig, PolicyRunner, RunningMeanStd};
use rlnav_sim::LidarSpec;
use rlnav_sim::task::ObservationLayout;
use std::path::{Path, PathBuf};

fn contract(io: GraphIo) -> PolicyContract {
    PolicyContract {
        format: CONTRACT_FORMAT,
        producer: "test".into(),
        task: "parity".into(),
        robot: "jetbot".into(),
        observation: ObservationLayout::default(),
        scan: ScanContract::of(&LidarSpec::default()),
        action: ActionContract {
            scaling: ActionScaling::Normalized,
            linear: [0.1, 0.5],
            angular: [-0.5, 0.5],
            linear_relative: false,
        },
        control_period: 0.1,
        goal_tolerance: 0.3,
        io,
        plan: None,
        envelope: None,
    }
}

/// A normaliser with statistics that matter (means and spreads far from 0 and 1).
fn normaliser(n: usize, seed: u64) -> RunningMeanStd {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let mut norm = RunningMeanStd::new(n);
    let data: Vec<f32> = (0..n * 64).map(|i| rng.random_range(0.0..3.0) * (1.0 + (i % n) as f32 / n as f32)).collect();
    norm.update(&data);
    norm
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rlnav-onnx-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn burn_step(
    net: &ActorCritic,
    norm: &RunningMeanStd,
    obs: &[f32],
    state: Option<burn::nn::LstmState<2>>,
) -> (Vec<f32>, f32, Option<burn::nn::LstmState<2>>) {
    let device = Device::flex();
    let mut x = obs.to_vec();
    norm.normalize(&mut x);
    let t = Tensor::<2>::from_data(TensorData::new(x, [1, obs.len()]), &device);
    let (mu, v, next) = net.step(t, state);
    let mu: Vec<f32> = mu.into_data().try_to_vec().unwrap();
    let v: Vec<f32> = v.into_data().try_to_vec().unwrap();
    (mu, v[0], next)
}

fn random_obs(rng: &mut impl rand::Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0..4.0)).collect()
}

/// Writes the model, inputs and expected outputs for the ONNX Runtime check.
/// `outputs`: the graph outputs ONNX Runtime must find.
fn write_case(
    name: &str,
    bytes: &[u8],
    steps: &[Vec<f32>],
    expected: &[Vec<f32>],
    recurrent: bool,
    outputs: &[&str],
) -> PathBuf {
    let model = tmp(&format!("{name}.onnx"));
    std::fs::write(&model, bytes).unwrap();
    let case = serde_json::json!({
        "model": model, "recurrent": recurrent, "obs": steps, "mu": expected, "tolerance": 1e-5, "outputs": outputs,
    });
    let path = tmp(&format!("{name}.json"));
    std::fs::write(&path, case.to_string()).unwrap();
    path
}

/// Runs `tools/ort_parity.py` on the cases when a Python with onnxruntime is configured; in
/// CI it must be.
fn onnxruntime_check(cases: &[PathBuf]) {
    let Ok(python) = std::env::var("RLNAV_ORT_PYTHON") else {
        assert!(std::env::var("CI").is_err(), "CI must set RLNAV_ORT_PYTHON (a venv with onnx and onnxruntime)");
        eprintln!("RLNAV_ORT_PYTHON not set: ONNX Runtime parity skipped (CI runs it)");
        return;
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/ort_parity.py");
    let out = std::process::Command::new(python).arg(script).args(cases).output().expect("python runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "ONNX Runtime parity failed:\n{text}");
    eprintln!("{text}");
}

#[test]
fn mlp_and_lstm_exports_match_burn_tract_and_onnxruntime() {
    let device = Device::flex();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
    let mut cases = Vec::new();
    for (name, cfg) in [
        ("mlp", NetworkConfig { hidden: vec![64, 32], ..Default::default() }),
        (
            "mlp-shared-relu",
            NetworkConfig {
                hidden: vec![48],
                activation: ActivationKind::Relu,
                separate_critic: false,
                ..Default::default()
            },
        ),
        ("lstm", NetworkConfig { hidden: vec![64, 32], lstm_units: 24, init_log_std: -0.7, ..Default::default() }),
    ] {
        let net = ActorCritic::seeded(&cfg, 124, 2, &device, 7);
        let norm = normaliser(124, 3);
        let io = if cfg.is_recurrent() { lstm_io(24) } else { GraphIo::default() };
        let c = contract(io);
        let proto = export_model(&net, &norm, &c).unwrap();
        let bytes = proto.encode_to_vec();
        assert_eq!(proto.opset_import[0].version, 14);
        let mut runner = PolicyRunner::from_proto(name, &proto, c.clone()).unwrap();
        let steps: Vec<Vec<f32>> =
            (0..if cfg.is_recurrent() { 50 } else { 20 }).map(|_| random_obs(&mut rng, 124)).collect();
        let mut state = None;
        let mut expected = Vec::new();
        let mut worst = 0.0f32;
        for obs in &steps {
            let (mu, value, next) = burn_step(&net, &norm, obs, state);
            state = next;
            let out = runner.infer(obs).unwrap();
            worst = worst.max((out.mu[0] - mu[0]).abs()).max((out.mu[1] - mu[1]).abs());
            worst = worst.max((out.value.unwrap() - value).abs());
            expected.push(mu);
            if !cfg.is_recurrent() {
                // A feed-forward policy carries nothing from one step to the next.
                runner.infer(&random_obs(&mut rng, 124)).unwrap();
            }
        }
        assert!(worst <= 1e-5, "{name}: tract differs from burn by {worst}");
        // The contract comes back out of the file as it went in.
        let back = rlnav_policy::runner::embedded_contract(&proto, name).unwrap().unwrap();
        assert_eq!(back, c);
        cases.push(write_case(name, &bytes, &steps, &expected, cfg.is_recurrent(), &["mu", "log_std", "value"]));
    }
    onnxruntime_check(&cases);
}

/// The plain layers' forward pass by hand, as PyTorch computes it.
fn plain_forward(layers: &[DenseLayer], norm: &ObsAffine, obs: &[f32]) -> Vec<f32> {
    let mut x: Vec<f32> = obs
        .iter()
        .zip(norm.scale.iter().zip(&norm.shift))
        .map(|(o, (a, b))| (o * a + b).clamp(-norm.clip, norm.clip))
        .collect();
    for l in layers {
        let mut y = l.bias.clone();
        for (i, xi) in x.iter().enumerate() {
            for (o, yo) in y.iter_mut().enumerate() {
                *yo += xi * l.weight[i * l.outputs + o];
            }
        }
        for v in &mut y {
            *v = match l.activation {
                Some(ActivationKind::Tanh) => v.tanh(),
                Some(ActivationKind::Relu) => v.max(0.0),
                Some(ActivationKind::Elu) => {
                    if *v > 0.0 {
                        *v
                    } else {
                        v.exp_m1()
                    }
                }
                None => *v,
            };
        }
        x = y;
    }
    x
}

#[test]
fn plain_mlp_export_matches_its_forward_pass_tract_and_onnxruntime() {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
    let mut layer = |inputs: usize, outputs: usize, activation| DenseLayer {
        weight: (0..inputs * outputs).map(|_| rng.random_range(-0.3..0.3)).collect(),
        inputs,
        outputs,
        bias: (0..outputs).map(|_| rng.random_range(-0.1..0.1)).collect(),
        activation,
    };
    let layers = vec![
        layer(124, 64, Some(ActivationKind::Tanh)),
        layer(64, 32, Some(ActivationKind::Relu)),
        layer(32, 16, Some(ActivationKind::Elu)),
        layer(16, 2, None),
    ];
    let (scale, shift) = normaliser(124, 4).affine();
    let norm = ObsAffine { scale, shift, clip: 10.0 };
    let c = contract(GraphIo::default());
    let proto = export_mlp(&layers, &norm, &c).unwrap();
    let mut runner = PolicyRunner::from_proto("plain", &proto, c.clone()).unwrap();
    assert_eq!(rlnav_policy::runner::embedded_contract(&proto, "plain").unwrap().unwrap(), c);
    let steps: Vec<Vec<f32>> = (0..20).map(|_| random_obs(&mut rng, 124)).collect();
    let mut expected = Vec::new();
    for obs in &steps {
        let want = plain_forward(&layers, &norm, obs);
        let got = runner.infer(obs).unwrap().mu;
        assert!((got[0] - want[0]).abs() <= 1e-5 && (got[1] - want[1]).abs() <= 1e-5, "{got:?} vs {want:?}");
        assert!(runner.infer(obs).unwrap().value.is_none(), "an actor alone has no value output");
        expected.push(want);
    }
    onnxruntime_check(&[write_case("plain-mlp", &proto.encode_to_vec(), &steps, &expected, false, &["mu"])]);

    // What does not fit is refused with what was expected.
    let err = |layers: &[DenseLayer], norm: &ObsAffine| export_mlp(layers, norm, &c).unwrap_err().to_string();
    assert!(err(&layers[1..], &norm).contains("layer 0 takes 64 values, expected 124"));
    assert!(err(&layers[..3], &norm).contains("2 outputs and no activation, got 16"));
    assert!(err(&layers, &ObsAffine::identity(60)).contains("124 values, the normaliser's scale 60"));
    let mut nan = layers.clone();
    nan[2].weight[3] = f32::NAN;
    assert!(err(&nan, &norm).contains("layer 2: expected finite weights"));
    let mut short = layers.clone();
    short[1].bias.pop();
    assert!(err(&short, &norm).contains("layer 1: expected 64×32 weights and 32 biases, got 2048 and 31"));
}

#[test]
fn models_that_do_not_fit_their_contract_fail_at_load() {
    let device = Device::flex();
    let net = ActorCritic::seeded(&NetworkConfig { hidden: vec![16], ..Default::default() }, 124, 2, &device, 1);
    let proto = export_model(&net, &normaliser(124, 1), &contract(GraphIo::default())).unwrap();
    // The contract says 63 values; the graph takes 124.
    let mut short = contract(GraphIo::default());
    use rlnav_sim::task::ObsTerm;
    short.observation = ObservationLayout(vec![
        ObsTerm::Lidar { beams: 60, clip: [0.15, 2.0], sweep: 0.0 },
        ObsTerm::GoalDistance,
        ObsTerm::GoalBearing,
        ObsTerm::LastLinear,
    ]);
    let e = PolicyRunner::from_proto("short.onnx", &proto, short).unwrap_err().to_string();
    assert!(e.contains("short.onnx") && e.contains("`obs`") && e.contains("63 values"), "{e}");
    // A recurrent contract for a feed-forward graph.
    let e = PolicyRunner::from_proto("ff.onnx", &proto, contract(lstm_io(8))).unwrap_err().to_string();
    assert!(e.contains("no state input `out_state.1`"), "{e}");
    // Files: missing, not ONNX, ONNX without a contract.
    let e = PolicyRunner::load(Path::new("missing.onnx"), None).unwrap_err().to_string();
    assert!(e.contains("missing.onnx") && e.contains("cannot read"), "{e}");
    let junk = tmp("junk.onnx");
    std::fs::write(&junk, b"definitely not protobuf \xff\xff\xff").unwrap();
    let e = PolicyRunner::load(&junk, None).unwrap_err().to_string();
    assert!(e.contains("junk.onnx") && e.contains("not a loadable ONNX model"), "{e}");
    let mut bare = proto.clone();
    bare.metadata_props.clear();
    let bare_path = tmp("bare.onnx");
    std::fs::write(&bare_path, bare.encode_to_vec()).unwrap();
    let e = PolicyRunner::load(&bare_path, None).unwrap_err().to_string();
    assert!(e.contains("bare.onnx") && e.contains("rlnav.contract") && e.contains("--contract"), "{e}");
    // A side contract with a bad value names its file and key.
    let side = tmp("side.yaml");
    std::fs::write(
        &side,
        contract(GraphIo::default()).to_yaml().replace("control_period: 0.1", "control_period: -1.0"),
    )
    .unwrap();
    let e = PolicyRunner::load(&bare_path, Some(&side)).unwrap_err().to_string();
    assert!(e.contains("side.yaml") && e.contains("control_period"), "{e}");
}
