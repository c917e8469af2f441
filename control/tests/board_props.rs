//! The board's logic fed arbitrary host frames, commands and measurements: it never panics,
//! the bridge is off whenever a fault is latched, and the voltage never exceeds its limit.
use control::blob::Coefficients;
use control::board::{Board, Drive, Measurements, MAX_DUTY};
use control::frame::{encode_frame, Excitation, FrameDecoder, HostMsg, Mode, MAX_ENCODED_LEN};
use control::step::HallEdge;
use proptest::prelude::*;

/// Any f32, the awkward ones (NaN, infinities, huge, tiny, negative zero) often.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        -50.0f32..50.0,
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(f32::MAX),
        Just(-1e30f32),
        Just(-0.0f32),
        Just(1e-30f32),
        proptest::num::f32::ANY,
    ]
}

fn excitation() -> impl Strategy<Value = Excitation> {
    prop_oneof![
        Just(Excitation::A),
        Just(Excitation::B),
        Just(Excitation::C),
        Just(Excitation::D),
        any_f32().prop_map(|volts| Excitation::Steady { volts }),
        any_f32().prop_map(|volts_per_s| Excitation::Ramp { volts_per_s }),
    ]
}

fn mode() -> impl Strategy<Value = Mode> {
    prop_oneof![
        Just(Mode::Idle),
        Just(Mode::Speed),
        Just(Mode::Experiment),
        Just(Mode::Commission),
    ]
}

fn host_msg() -> impl Strategy<Value = HostMsg> {
    prop_oneof![
        Just(HostMsg::Identify),
        any_f32().prop_map(|omega_ref| HostMsg::SetSpeed { omega_ref }),
        mode().prop_map(|mode| HostMsg::SetMode { mode }),
        (excitation(), any_f32())
            .prop_map(|(signal, duration_s)| HostMsg::StartExperiment { signal, duration_s }),
        (excitation(), 0.0f32..5.0)
            .prop_map(|(signal, duration_s)| HostMsg::StartExperiment { signal, duration_s }),
        Just(HostMsg::Stop),
        Just(HostMsg::ClearFault),
        Just(HostMsg::Heartbeat),
        Just(HostMsg::Commission),
        Just(HostMsg::ReadCommission),
        Just(HostMsg::UploadCommit),
        (any::<u16>(), any::<u32>())
            .prop_map(|(total_len, crc)| HostMsg::UploadBegin { total_len, crc }),
    ]
}

fn measurements() -> impl Strategy<Value = Measurements> {
    (
        0u8..8,
        proptest::collection::vec((any::<u32>(), 0u8..8), 0..4),
        proptest::bool::weighted(0.02),
        any::<u32>(),
        prop_oneof![-2.0f32..2.0, any_f32()],
        prop_oneof![Just(24.0f32), 5.0f32..30.0, any_f32()],
        proptest::bool::weighted(0.02),
    )
        .prop_map(
            |(hall, edges, edges_overflow, now_ticks, i_vector, v_bus, overrun)| {
                let mut m = Measurements {
                    hall,
                    edges_overflow,
                    now_ticks,
                    i_vector,
                    v_bus,
                    overrun,
                    ..Measurements::default()
                };
                for (ticks, state) in edges {
                    let _ = m.edges.push(HallEdge { ticks, state });
                }
                m
            },
        )
}

/// One event of a run: a host message, a frame of raw bytes, or control periods.
#[derive(Debug, Clone)]
enum Event {
    Msg(HostMsg),
    Bytes(Vec<u8>),
    Ticks(Box<Measurements>, u8),
}

fn event() -> impl Strategy<Value = Event> {
    prop_oneof![
        3 => host_msg().prop_map(Event::Msg),
        1 => proptest::collection::vec(any::<u8>(), 0..40).prop_map(Event::Bytes),
        4 => (measurements(), 1u8..20).prop_map(|(m, n)| Event::Ticks(Box::new(m), n)),
    ]
}

/// The largest voltage a drive applies.
fn volts(d: &Drive) -> f32 {
    match *d {
        Drive::Off => 0.0,
        Drive::SixStep { volts, .. } | Drive::Centre { volts, .. } => volts,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn any_sequence_keeps_the_bridge_off_in_a_fault(
        events in proptest::collection::vec(event(), 1..40),
        with_coefficients in proptest::bool::ANY,
    ) {
        let loaded = with_coefficients.then(|| (Coefficients::default(), 1));
        let mut board = Board::new(loaded, "proptest", 24.0);
        let u_max = board.coefficients().pi.u_max;
        let mut decoder = FrameDecoder::new();
        let mut sink = |_msg| {};
        for e in events {
            match e {
                Event::Msg(msg) => {
                    // Through the wire format, as the transport receives it.
                    let mut buf = [0u8; MAX_ENCODED_LEN];
                    let frame = encode_frame(&msg, &mut buf).unwrap().to_vec();
                    for b in frame {
                        if let Some(Ok(m)) = decoder.push::<HostMsg>(b) {
                            board.handle(&m, &mut sink);
                        }
                    }
                }
                Event::Bytes(bytes) => {
                    for b in bytes {
                        if let Some(Ok(m)) = decoder.push::<HostMsg>(b) {
                            board.handle(&m, &mut sink);
                        }
                    }
                }
                Event::Ticks(m, n) => {
                    for _ in 0..n {
                        let drive = board.tick(&m, &mut sink);
                        if board.fault().is_some() {
                            prop_assert_eq!(drive, Drive::Off, "fault {:?}", board.fault());
                        }
                        let v = volts(&drive);
                        prop_assert!(v.is_finite(), "drive {:?}", drive);
                        let bus = if m.v_bus.is_finite() && m.v_bus > 0.0 { m.v_bus } else { 24.0 };
                        let limit = u_max.min(MAX_DUTY * bus);
                        prop_assert!(v.abs() <= limit * (1.0 + 1e-6), "drive {:?}, limit {}", drive, limit);
                    }
                }
            }
        }
    }
}
