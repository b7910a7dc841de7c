use motionlab::emulator::cache::EmulatorCache;
use motionlab::emulator::catalog::{TrainMethod, TrainSettings};
use motionlab::emulator::hierarchy::*;
use motionlab::physics::dolphin::Dolphin;
fn main() {
    let ts = TrainSettings { held_out_fraction: 0.25, cg_max_iters: 3000, max_epochs: 60, patience: 8, min_improvement: 0.001, learning_rate: 0.05, momentum: 0.9, batch_size: 30 };
    let base = HierarchySpec { global: HierarchyNet{hidden:50, examples:64000, method: TrainMethod::Momentum}, local: HierarchyNet{hidden:40, examples:32000, method: TrainMethod::Momentum}, physical_dt:0.002, steps:50, settings: ts, seed: motionlab::experiment::mix_seed(1, motionlab::emulator::cache::fnv1a(b"dolphin-n50")) };
    let built = build_dolphin(&base, &EmulatorCache::from_env()).unwrap();
    println!("cached {}", built.nets[0].from_cache);
    let d = Dolphin::default();
    let held = sample_dolphin(&d, 0.002, 50, 3000, 77).unwrap();
    let g = global_transitions(&d, &held);
    let e = built.emulator.global();
    let t = e.transforms();
    let ds = t.encode(&g);
    let mut sc = e.mlp().scratch();
    let mut y = vec![0.0; 78];
    let mut err = vec![0.0; 78];
    for r in 0..ds.len() {
        e.mlp().forward(ds.inputs.row(r).as_slice().unwrap(), &mut sc, &mut y);
        for k in 0..78 { err[k] += (y[k]-ds.targets[[r,k]]).powi(2) / ds.len() as f64; }
    }
    let names = ["cx","cy","cz","qw","qx","qy","qz","vx","vy","vz","wx","wy","wz"];
    for k in 0..13 { let m: f64 = (0..6).map(|s| err[13*s+k]).sum::<f64>()/6.0; println!("{} {:.3}  per seg {:?}", names[k], m, (0..6).map(|s| (err[13*s+k]*100.0).round()/100.0).collect::<Vec<_>>()); }
}
