use motorid::emulator::*;
#[test]
fn scratch() {
    let kind = SignalKind::C;
    let u = signal(kind, 8.0, 5);
    let run = |h: f64| { let cfg = EmulatorConfig { fine_step: h, current_noise: 0.0, ..EmulatorConfig::paper() }; simulate(&cfg, &u, SAMPLE_PERIOD).unwrap().truth };
    let hs = [0.4e-3, 0.2e-3, 0.1e-3, 0.05e-3, 0.025e-3,0.0125e-3];
    let rs: Vec<_> = hs.iter().map(|h| run(*h)).collect();
    for k in 440..530 {
        let row: Vec<String> = rs.iter().map(|r| format!("{:8.4}", r.omega[k])).collect();
        let zr: Vec<String> = rs.iter().map(|r| format!("{:9.2e}", r.z[k])).collect();
        println!("{k} u={:.3} w: {} z: {}", u[k], row.join(" "), zr.join(" "));
    }
}
