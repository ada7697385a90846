//! Times, for each deep-learning framework candidate, one PPO minibatch update of the actor and
//! critic MLPs of the article (124 -> 256 -> 128 -> 64 -> {2, 1}, ELU; batch 4096; clipped
//! surrogate + value loss, backward, gradient clipping, Adam) and one batch-1024 actor
//! inference, on the CPU. Prints one JSON line per framework.

use std::time::Instant;

const OBS: usize = 124;
const BATCH: usize = 4096;
const INFER: usize = 1024;
const HIDDEN: [usize; 3] = [256, 128, 64];

fn report(name: &str, threads: usize, update_ms: Vec<f64>, infer_ms: Vec<f64>) {
    let med = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{{\"framework\":\"{name}\",\"threads\":{threads},\"update_ms_p50\":{:.3},\"infer1024_ms_p50\":{:.4}}}",
        med(update_ms),
        med(infer_ms)
    );
}

fn threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}

#[cfg(feature = "candle")]
mod with_candle {
    use super::*;
    use candle_core::{D, DType, Device, Result, Tensor};
    use candle_nn::{AdamW, Linear, Module, Optimizer, ParamsAdamW, VarBuilder, VarMap, linear};

    struct Mlp(Vec<Linear>);

    impl Mlp {
        fn new(vb: VarBuilder, out: usize) -> Result<Self> {
            let mut sizes = vec![OBS];
            sizes.extend(HIDDEN);
            sizes.push(out);
            let layers = (0..sizes.len() - 1)
                .map(|i| linear(sizes[i], sizes[i + 1], vb.pp(format!("l{i}"))))
                .collect::<Result<Vec<_>>>()?;
            Ok(Self(layers))
        }
        fn forward(&self, x: &Tensor) -> Result<Tensor> {
            let mut x = x.clone();
            for (i, l) in self.0.iter().enumerate() {
                x = l.forward(&x)?;
                if i + 1 < self.0.len() {
                    x = x.elu(1.0)?;
                }
            }
            Ok(x)
        }
    }

    pub fn run(iters: usize) -> Result<()> {
        let dev = Device::Cpu;
        let vm = VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &dev);
        let actor = Mlp::new(vb.pp("actor"), 2)?;
        let critic = Mlp::new(vb.pp("critic"), 1)?;
        let log_std = vb.get_with_hints(2, "log_std", candle_nn::Init::Const(0.0))?;
        let vars = vm.all_vars();
        let mut opt = AdamW::new(vars.clone(), ParamsAdamW { lr: 3e-4, weight_decay: 0.0, ..Default::default() })?;
        let obs = Tensor::randn(0f32, 1.0, (BATCH, OBS), &dev)?;
        let act = Tensor::randn(0f32, 1.0, (BATCH, 2), &dev)?;
        let old_logp = Tensor::randn(0f32, 1.0, BATCH, &dev)?;
        let adv = Tensor::randn(0f32, 1.0, BATCH, &dev)?;
        let ret = Tensor::randn(0f32, 1.0, BATCH, &dev)?;
        let mut update_ms = Vec::new();
        for _ in 0..iters {
            let t = Instant::now();
            let mu = actor.forward(&obs)?;
            let std = log_std.exp()?;
            let z = act.broadcast_sub(&mu)?.broadcast_div(&std)?;
            let logp = ((z.sqr()? * -0.5)?.broadcast_sub(&log_std)? - 0.918_938_5)?.sum(D::Minus1)?;
            let ratio = (logp - &old_logp)?.exp()?;
            let surr = Tensor::minimum(&(&ratio * &adv)?, &(ratio.clamp(0.8f32, 1.2f32)? * &adv)?)?;
            let v = critic.forward(&obs)?.squeeze(1)?;
            let vloss = (v - &ret)?.sqr()?.mean_all()?;
            let loss = ((surr.mean_all()? * -1.0)? + (vloss * 2.0)?)?;
            let mut grads = loss.backward()?;
            // Global gradient-norm clipping to 1.0.
            let mut sq = 0f32;
            for var in &vars {
                if let Some(g) = grads.get(var) {
                    sq += g.sqr()?.sum_all()?.to_scalar::<f32>()?;
                }
            }
            let scale = (1.0 / sq.sqrt().max(1.0)) as f64;
            for var in &vars {
                if let Some(g) = grads.remove(var) {
                    grads.insert(var, (g * scale)?);
                }
            }
            opt.step(&grads)?;
            update_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let x = Tensor::randn(0f32, 1.0, (INFER, OBS), &dev)?;
        let mut infer_ms = Vec::new();
        for _ in 0..iters * 10 {
            let t = Instant::now();
            let y = actor.forward(&x)?;
            std::hint::black_box(y.to_vec2::<f32>()?);
            infer_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        report("candle", threads(), update_ms, infer_ms);
        Ok(())
    }
}

#[cfg(feature = "burn")]
mod with_burn {
    use super::*;
    use burn::module::Param;
    use burn::nn::{Linear, LinearConfig};
    use burn::optim::{AdamConfig, GradientsParams};
    use burn::prelude::*;
    use burn::tensor::Distribution;
    use burn::tensor::activation::elu;

    #[derive(Module, Debug)]
    struct Mlp {
        layers: Vec<Linear>,
    }

    impl Mlp {
        fn new(out: usize, device: &Device) -> Self {
            let mut sizes = vec![OBS];
            sizes.extend(HIDDEN);
            sizes.push(out);
            Self { layers: (0..sizes.len() - 1).map(|i| LinearConfig::new(sizes[i], sizes[i + 1]).init(device)).collect() }
        }
        fn forward(&self, mut x: Tensor<2>) -> Tensor<2> {
            let n = self.layers.len();
            for (i, l) in self.layers.iter().enumerate() {
                x = l.forward(x);
                if i + 1 < n {
                    x = elu(x, 1.0);
                }
            }
            x
        }
    }

    #[derive(Module, Debug)]
    struct ActorCritic {
        actor: Mlp,
        critic: Mlp,
        log_std: Param<Tensor<1>>,
    }

    pub fn run(iters: usize) {
        let device = Device::flex().autodiff();
        let mut model = ActorCritic {
            actor: Mlp::new(2, &device),
            critic: Mlp::new(1, &device),
            log_std: Param::from_tensor(Tensor::zeros([2], &device)),
        };
        let mut opt = AdamConfig::new()
            .with_grad_clipping(Some(burn::grad_clipping::GradientClippingConfig::Norm(1.0)))
            .init();
        let normal = Distribution::Normal(0.0, 1.0);
        let obs = Tensor::<2>::random([BATCH, OBS], normal, &device);
        let act = Tensor::<2>::random([BATCH, 2], normal, &device);
        let old_logp = Tensor::<1>::random([BATCH], normal, &device);
        let adv = Tensor::<1>::random([BATCH], normal, &device);
        let ret = Tensor::<1>::random([BATCH], normal, &device);
        let mut update_ms = Vec::new();
        for _ in 0..iters {
            let t = Instant::now();
            let mu = model.actor.forward(obs.clone());
            let log_std = model.log_std.val().unsqueeze::<2>();
            let z = (act.clone() - mu) / log_std.clone().exp();
            let logp: Tensor<1> = (z.powf_scalar(2.0) * -0.5 - log_std - 0.918_938_5).sum_dim(1).squeeze_dim(1);
            let ratio = (logp - old_logp.clone()).exp();
            let surr = (ratio.clone() * adv.clone()).min_pair(ratio.clamp(0.8, 1.2) * adv.clone());
            let v: Tensor<1> = model.critic.forward(obs.clone()).squeeze_dim(1);
            let vloss = (v - ret.clone()).powf_scalar(2.0).mean();
            let loss = surr.mean() * -1.0 + vloss * 2.0;
            let grads = GradientsParams::from_grads(loss.backward(), &model);
            model = opt.step(3e-4, model, grads);
            let _ = model.log_std.val().into_data();
            update_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let x = Tensor::<2>::random([INFER, OBS], normal, &Device::flex());
        let actor = model.actor.valid();
        let mut infer_ms = Vec::new();
        for _ in 0..iters * 10 {
            let t = Instant::now();
            std::hint::black_box(actor.forward(x.clone()).into_data());
            infer_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        report("burn-flex", threads(), update_ms, infer_ms);
    }
}

fn main() {
    let iters: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(30);
    #[cfg(feature = "candle")]
    with_candle::run(iters).expect("candle benchmark");
    #[cfg(feature = "burn")]
    with_burn::run(iters);
    let _ = iters;
}
