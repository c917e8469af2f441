//! Criterion bench: `diagnose` on 10^5 samples (20 minutes of the paper's 12 ms log) of the
//! emulated motor with a hidden cogging torque, against a LuGre structure. Target: < 2 s.
use control::effects::Effect;
use criterion::{criterion_group, criterion_main, Criterion};
use motorid::diagnose::{diagnose, Options, Structure};
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind, SAMPLE_PERIOD};
use motorid::log::Plant;

fn bench(c: &mut Criterion) {
    let mut cfg = EmulatorConfig::paper();
    cfg.effects.push(Effect::Cogging {
        harmonic: 7,
        amp: 0.03,
        phase: 0.0,
    });
    let log = simulate_signal(&cfg, SignalKind::A, 100_000.0 * SAMPLE_PERIOD)
        .expect("emulator")
        .log;
    let st = Structure::lugre_paper(Plant::Voltage);
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    g.bench_function("1e5_samples_lugre", |b| {
        b.iter(|| diagnose(&log, &st, &Options::default()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
