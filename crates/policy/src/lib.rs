//! `rlnav-policy`: the networks a navigation policy is made of (MLP and LSTM actor-critics on
//! burn), the running observation normalisation saved and exported with them, the device
//! they run on, and the policy as a file: ONNX export with the [`PolicyContract`] inside, and
//! [`PolicyRunner`], which runs any contracted ONNX policy (tract) as a `Controller`. It knows
//! nothing of PPO.

pub mod contract;
pub mod export;
pub mod network;
pub mod normalizer;
pub mod runner;
pub mod scan;

pub use contract::PolicyContract;
pub use network::{ActivationKind, ActorCritic, NetworkConfig, training_device};
pub use normalizer::RunningMeanStd;
pub use runner::PolicyRunner;
