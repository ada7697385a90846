//! Re-sampling a robot's scan to the geometry a policy was trained on: any beam count, start
//! angle, field of view and mount rotation in, the contract's beams (in its order) out.
//!
//! Each incoming beam is rotated into `base_link` by the lidar's mount yaw and falls into the
//! contract beam whose angular cell contains it; a contract beam takes the minimum of its
//! incoming beams (thin obstacles survive), or, when it received none (a sparser scanner), the
//! nearest incoming beam within two increments. A contract sector the scanner does not see at
//! all cannot be adapted: the policy would read free space there.
//!
//! Readings: NaN or above `range_max` is no return (`+inf`); below `range_min` (including the
//! 0 some drivers send) is something closer than the sensor can measure, read as the
//! contract's `range_min`.

use crate::contract::ScanContract;
use rlnav_sim::LaserScan;
use rlnav_sim::geometry::wrap_angle;
use std::f32::consts::TAU;

/// Largest share of contract beams an incoming scan may leave uncovered.
pub const MAX_UNCOVERED: f32 = 0.02;

/// Why a scan cannot feed a policy.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ScanError {
    /// The scan's geometry leaves part of the policy's field of view unseen.
    #[error(
        "scan of {beams} beams from {angle_min:.4} rad every {increment:.5} rad (mount yaw {yaw:.3}) leaves \
         {uncovered} of the policy's {contract} beams unseen (the policy expects {fov:.1}° from {cmin:.4} rad)"
    )]
    Coverage {
        /// Incoming beams.
        beams: usize,
        /// Incoming angle_min.
        angle_min: f32,
        /// Incoming angle_increment.
        increment: f32,
        /// Mount yaw.
        yaw: f32,
        /// Contract beams without data.
        uncovered: usize,
        /// Contract beams.
        contract: usize,
        /// Contract field of view (degrees).
        fov: f32,
        /// Contract angle_min.
        cmin: f32,
    },
    /// Malformed scan metadata.
    #[error("malformed scan: {0}")]
    Malformed(String),
    /// Too many readings are NaN.
    #[error("{nan} of {beams} readings are NaN")]
    Garbage {
        /// NaN readings.
        nan: usize,
        /// Beams.
        beams: usize,
    },
}

/// A mapping from one incoming scan geometry to the contract's beams.
#[derive(Clone, Debug)]
pub struct ScanAdapter {
    contract: ScanContract,
    key: (usize, u32, u32, u32),
    /// For each incoming beam, its contract beam (or none when outside the contract's view).
    bin: Vec<Option<u32>>,
    /// For each contract beam that receives no incoming beam, the nearest incoming one.
    fill: Vec<Option<u32>>,
    identity: bool,
}

impl ScanAdapter {
    /// The mapping for scans of this geometry, or why there is none.
    pub fn new(contract: &ScanContract, scan: &LaserScan, mount_yaw: f32) -> Result<Self, ScanError> {
        let n_in = scan.ranges.len();
        if n_in == 0 || !scan.angle_increment.is_finite() || scan.angle_increment <= 0.0 || !scan.angle_min.is_finite()
        {
            return Err(ScanError::Malformed(format!(
                "{n_in} ranges, angle_min {}, angle_increment {}",
                scan.angle_min, scan.angle_increment
            )));
        }
        let spec = contract.lidar_spec();
        let inc_c = spec.angle_increment();
        let full = spec.is_full_circle();
        let m = contract.beams;
        let key = (n_in, scan.angle_min.to_bits(), scan.angle_increment.to_bits(), mount_yaw.to_bits());
        // Contract index (fractional) of a base-frame angle.
        let index_of = |phi: f32| -> Option<usize> {
            let rel =
                if full { wrap_angle(phi - spec.angle_min).rem_euclid(TAU) } else { wrap_angle(phi - spec.angle_min) };
            let k = (rel / inc_c).round();
            let k = if full {
                k as usize % m
            } else if k >= 0.0 && (k as usize) < m {
                k as usize
            } else {
                return None;
            };
            Some(contract.from_ccw(k))
        };
        let angle_in = |i: usize| mount_yaw + scan.angle_min + i as f32 * scan.angle_increment;
        let bin: Vec<Option<u32>> = (0..n_in).map(|i| index_of(angle_in(i)).map(|k| k as u32)).collect();
        let mut hit = vec![false; m];
        for b in bin.iter().flatten() {
            hit[*b as usize] = true;
        }
        let identity = n_in == m
            && bin.iter().enumerate().all(|(i, b)| *b == Some(i as u32))
            && (scan.angle_increment - inc_c).abs() < 1e-6;
        let mut fill = vec![None; m];
        let mut uncovered = 0;
        if !identity {
            // Incoming beams sorted by angle for the nearest-beam search.
            for j in (0..m).filter(|j| !hit[*j]) {
                let theta = contract.beam_angle(j);
                let rel = wrap_angle(theta - mount_yaw - scan.angle_min).rem_euclid(TAU);
                let k = (rel / scan.angle_increment).round() as usize;
                let candidates = [k.checked_sub(1), Some(k), Some(k + 1)];
                let best = candidates
                    .into_iter()
                    .flatten()
                    .filter_map(|i| {
                        let i =
                            if i >= n_in && scan.angle_increment * n_in as f32 >= TAU - 1e-3 { i % n_in } else { i };
                        (i < n_in).then(|| (i, wrap_angle(angle_in(i) - theta).abs()))
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                match best {
                    Some((i, d)) if d <= 2.0 * scan.angle_increment.max(inc_c) => fill[j] = Some(i as u32),
                    _ => uncovered += 1,
                }
            }
        }
        if uncovered as f32 > MAX_UNCOVERED * m as f32 {
            return Err(ScanError::Coverage {
                beams: n_in,
                angle_min: scan.angle_min,
                increment: scan.angle_increment,
                yaw: mount_yaw,
                uncovered,
                contract: m,
                fov: (if full { TAU } else { spec.angle_max - spec.angle_min }).to_degrees(),
                cmin: spec.angle_min,
            });
        }
        Ok(Self { contract: contract.clone(), key, bin, fill, identity })
    }

    /// Whether this adapter was made for scans of this geometry.
    pub fn fits(&self, scan: &LaserScan, mount_yaw: f32) -> bool {
        self.key == (scan.ranges.len(), scan.angle_min.to_bits(), scan.angle_increment.to_bits(), mount_yaw.to_bits())
    }

    /// Writes the contract's beams (length `contract.beams`) from `scan`.
    pub fn adapt(&self, scan: &LaserScan, out: &mut [f32]) -> Result<(), ScanError> {
        let (c_min, c_max) = (self.contract.range_min, self.contract.range_max);
        let nan = scan.ranges.iter().filter(|r| r.is_nan()).count();
        if nan * 2 > scan.ranges.len() {
            return Err(ScanError::Garbage { nan, beams: scan.ranges.len() });
        }
        let clean = |r: f32| {
            if r.is_nan() || r > scan.range_max || r > c_max {
                f32::INFINITY
            } else if r < scan.range_min || r < c_min {
                c_min
            } else {
                r
            }
        };
        if self.identity {
            for (o, r) in out.iter_mut().zip(&scan.ranges) {
                *o = clean(*r);
            }
            return Ok(());
        }
        out.fill(f32::INFINITY);
        for (r, b) in scan.ranges.iter().zip(&self.bin) {
            if let Some(b) = b {
                let o = &mut out[*b as usize];
                *o = o.min(clean(*r));
            }
        }
        for (o, f) in out.iter_mut().zip(&self.fill) {
            if let Some(i) = f {
                *o = clean(scan.ranges[*i as usize]);
            }
        }
        Ok(())
    }
}
