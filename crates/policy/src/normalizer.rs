//! Running observation (and value) normalisation, as rl_games' `RunningMeanStd`: statistics
//! merged batch by batch with Chan's parallel algorithm, values standardised and clipped.
//! Saved with the model and exported into the ONNX graph, so a deployment feeds raw values.

use serde::{Deserialize, Serialize};

/// Running per-feature mean and variance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningMeanStd {
    /// Per-feature mean.
    pub mean: Vec<f64>,
    /// Per-feature (population) variance.
    pub var: Vec<f64>,
    /// Samples seen (starts at a tiny epsilon, as rl_games, so the first batch dominates).
    pub count: f64,
    /// Standardised values are clipped to `[-clip, clip]`.
    pub clip: f32,
}

/// Added to the variance before the square root.
pub const EPSILON: f64 = 1e-5;

impl RunningMeanStd {
    /// Statistics for `dim` features: mean 0, variance 1.
    pub fn new(dim: usize) -> Self {
        Self { mean: vec![0.0; dim], var: vec![1.0; dim], count: 1e-4, clip: 5.0 }
    }

    /// Number of features.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Merges a batch of rows (`data.len()` a multiple of `dim`).
    pub fn update(&mut self, data: &[f32]) {
        let d = self.dim();
        let n = data.len() / d;
        if n == 0 {
            return;
        }
        let mut bmean = vec![0.0f64; d];
        for row in data.chunks_exact(d) {
            for (m, x) in bmean.iter_mut().zip(row) {
                *m += *x as f64;
            }
        }
        bmean.iter_mut().for_each(|m| *m /= n as f64);
        let mut bvar = vec![0.0f64; d];
        for row in data.chunks_exact(d) {
            for ((v, x), m) in bvar.iter_mut().zip(row).zip(&bmean) {
                let e = *x as f64 - m;
                *v += e * e;
            }
        }
        bvar.iter_mut().for_each(|v| *v /= n as f64);
        let (na, nb) = (self.count, n as f64);
        let total = na + nb;
        for i in 0..d {
            let delta = bmean[i] - self.mean[i];
            self.mean[i] += delta * nb / total;
            let m2 = self.var[i] * na + bvar[i] * nb + delta * delta * na * nb / total;
            self.var[i] = m2 / total;
        }
        self.count = total;
    }

    /// Standardises rows in place: `clip((x - mean) / sqrt(var + eps))`.
    pub fn normalize(&self, data: &mut [f32]) {
        let d = self.dim();
        let (scale, shift) = self.affine();
        for row in data.chunks_exact_mut(d) {
            for ((x, s), b) in row.iter_mut().zip(&scale).zip(&shift) {
                *x = (*x * s + b).clamp(-self.clip, self.clip);
            }
        }
    }

    /// Inverse of [`Self::normalize`] (for unclipped values).
    pub fn denormalize(&self, data: &mut [f32]) {
        let d = self.dim();
        for row in data.chunks_exact_mut(d) {
            for (i, x) in row.iter_mut().enumerate() {
                *x = (*x as f64 * (self.var[i] + EPSILON).sqrt() + self.mean[i]) as f32;
            }
        }
    }

    /// The standardisation as `x * scale + shift` per feature (what the exported graph uses).
    pub fn affine(&self) -> (Vec<f32>, Vec<f32>) {
        let scale: Vec<f32> = self.var.iter().map(|v| (1.0 / (v + EPSILON).sqrt()) as f32).collect();
        let shift: Vec<f32> = self.mean.iter().zip(&scale).map(|(m, s)| (-m * *s as f64) as f32).collect();
        (scale, shift)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn batches_merge_like_one_big_batch() {
        let data: Vec<f32> = (0..3000).map(|i| ((i * 7919) % 1000) as f32 / 100.0 + (i % 3) as f32).collect();
        let mut one = RunningMeanStd::new(3);
        one.count = 0.0;
        one.update(&data);
        let mut many = RunningMeanStd::new(3);
        many.count = 0.0;
        for chunk in data.chunks(3 * 37) {
            many.update(chunk);
        }
        for i in 0..3 {
            assert!((one.mean[i] - many.mean[i]).abs() < 1e-9);
            assert!((one.var[i] - many.var[i]).abs() < 1e-9);
        }
    }

    proptest! {
        #[test]
        fn normalize_inverts(rows in prop::collection::vec(prop::collection::vec(-50.0f32..50.0, 4), 2..40)) {
            let flat: Vec<f32> = rows.concat();
            let mut s = RunningMeanStd::new(4);
            s.update(&flat);
            s.clip = f32::INFINITY;
            let mut x = flat.clone();
            s.normalize(&mut x);
            s.denormalize(&mut x);
            for (a, b) in x.iter().zip(&flat) {
                prop_assert!((a - b).abs() <= 1e-3 * (1.0 + b.abs()));
            }
        }
    }
}
