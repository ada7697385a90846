use rlnav_train::run::{load_model, read_run_config};
fn main() {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap());
    let cfg = read_run_config(&dir).unwrap();
    let device = rlnav_policy::training_device();
    let setup = std::sync::Arc::new(
        rlnav_sim::task::EnvSetup::new(
            rlnav_sim::ScenarioSpec::load(&cfg.eval.scenario).unwrap(),
            rlnav_sim::RobotSpec::load(&cfg.robot).unwrap(),
            cfg.task.clone(),
        )
        .unwrap(),
    );
    let mut ppo = rlnav_train::ppo::Ppo::new(&cfg.train, &cfg.network, 124, 2, device.clone(), 0);
    let model = load_model(&cfg, &dir.join("checkpoint"), 124, &device.clone().autodiff()).unwrap();
    let st: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoint/state.json")).unwrap()).unwrap();
    ppo.obs_norm = serde_json::from_value(st["obs_norm"].clone()).unwrap();
    ppo.restore(model, burn::optim::AdamConfig::new().init(), 1e-4);
    let (r, eps) = rlnav_train::eval::evaluate(&ppo, setup, 200, 50, 12345, 2).unwrap();
    println!("{r:?}");
    for e in eps.iter().filter(|e| e.outcome != rlnav_sim::Outcome::Success) {
        println!(
            "{:?} t={:.1} d0={:.2} dfinal={:.2} minr={:.2} speed={:.2}",
            e.outcome, e.time, e.initial_distance, e.final_distance, e.min_range, e.mean_speed
        );
    }
}
