//! Cost of the free runs a LuGre refinement is made of, on 90 s of signal a at 12 ms (7,500
//! samples; the paper's motor with a constant load torque, emulated), on the 2 s segments of
//! `fit --add` (group `free_run_90s`):
//!
//! - `f64_run`: the residuals of one model (a trial step, a grid point);
//! - `f64_run_recording`: the same, keeping the sub-steps' roots;
//! - `jacobian_solving`: the residuals and the exact Jacobian over the 11 free parameters
//!   (LuGre law, motor constants, the offset), two dual-number runs side by side on rayon's
//!   threads, each searching the sub-steps' roots;
//! - `jacobian_replaying`: the same from the recorded roots (what a refinement does).
//!
//! A refinement's iteration is one Jacobian and one or more trial runs.
use control::effects::Effect;
use criterion::{criterion_group, criterion_main, Criterion};
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind};
use motorid::ident::linear::{effect_free, lugre_free, motor_free};
use motorid::ident::sim_error::Residuals;
use motorid::log::Plant;
use motorid::model::{Model, ModelKind};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let mut cfg = EmulatorConfig::paper();
    cfg.effects = vec![Effect::Offset { t0: 0.03 }];
    let logs = [simulate_signal(&cfg, SignalKind::A, 90.0)
        .expect("emulated log")
        .log];
    let mut model = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
    model.motor = cfg.motor;
    model.lugre = Some(cfg.lugre);
    model.effects = cfg.effects.clone();
    let mut free = lugre_free();
    free.extend(motor_free(Plant::Voltage));
    free.extend(effect_free(&model));
    let res = Residuals::segmented(&logs, model.sensor.velocity_window);
    let (_, tape) = res.eval_recording(&model).expect("free run");

    let mut g = c.benchmark_group("free_run_90s");
    g.sample_size(10);
    g.bench_function("f64_run", |b| {
        b.iter(|| black_box(res.eval(black_box(&model)).unwrap()))
    });
    g.bench_function("f64_run_recording", |b| {
        b.iter(|| black_box(res.eval_recording(black_box(&model)).unwrap()))
    });
    g.bench_function("jacobian_solving", |b| {
        b.iter(|| {
            black_box(
                res.eval_with_jacobian(black_box(&model), &free, None)
                    .unwrap(),
            )
        })
    });
    g.bench_function("jacobian_replaying", |b| {
        b.iter(|| {
            black_box(
                res.eval_with_jacobian(black_box(&model), &free, Some(&tape))
                    .unwrap(),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
