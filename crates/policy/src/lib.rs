//! `rlnav-policy`: the networks a navigation policy is made of (MLP and LSTM actor-critics on
//! burn), the running observation normalisation saved and exported with them, and the device
//! they run on. It knows nothing of PPO.

pub mod network;
pub mod normalizer;

pub use network::{ActivationKind, ActorCritic, NetworkConfig, training_device};
pub use normalizer::RunningMeanStd;
