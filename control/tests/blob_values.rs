//! Coefficient blobs with values in and out of the board's ratings: in range they encode and
//! decode to the same coefficients; out of range (or not finite) both refuse them; nothing
//! panics, and a blob whose CRC is right but whose values are not is refused on decode.
use control::blob::{
    self, BlobError, Coefficients, Estimator, CRC32, HEADER_LEN, MAX_BLOB_LEN, MAX_COMP_GAIN,
    MAX_KI, MAX_KP, RATED_I_MAX, RATED_VBUS_MAX,
};
use proptest::prelude::*;

/// Values around and far beyond each range, and the non-finite ones.
fn value(hi: f32) -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => 0.0f32..=hi,
        1 => -hi..0.0f32,
        1 => hi..(4.0 * hi),
        1 => prop_oneof![
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(-1e30f32),
            Just(1e30f32),
            Just(0.0f32),
            Just(hi),
        ],
    ]
}

/// What the ratings allow, written out independently of `validate`.
fn allowed(c: &Coefficients) -> bool {
    let (p, l) = (&c.pi, &c.limits);
    let within = |x: f32, hi: f32| (0.0..=hi).contains(&x);
    within(p.kp, MAX_KP)
        && within(p.ki, MAX_KI)
        && within(p.comp_gain, MAX_COMP_GAIN)
        && within(p.u_max, RATED_VBUS_MAX)
        && p.u_max > 0.0
        && within(l.i_max, RATED_I_MAX)
        && l.i_max > 0.0
        && within(l.vbus_min, RATED_VBUS_MAX)
        && within(l.vbus_max, RATED_VBUS_MAX)
        && l.vbus_min < l.vbus_max
        // A winding of 10 µΩ to 10 kΩ.
        && (1e-5..=1e4).contains(&c.motor.r)
        && match c.estimator {
            Estimator::MovingAverage { window } => (1..=64).contains(&window),
            Estimator::EdgeTiming { timeout_s } => timeout_s > 0.0 && timeout_s.is_finite(),
        }
}

/// A blob with a correct header and CRC around `c`'s encoding, whatever its values.
fn forged(c: &Coefficients) -> Vec<u8> {
    let mut payload = [0u8; MAX_BLOB_LEN];
    let n = postcard::to_slice(c, &mut payload).unwrap().len();
    let mut b = blob::MAGIC.to_vec();
    b.extend_from_slice(&blob::VERSION.to_le_bytes());
    b.extend_from_slice(&(n as u16).to_le_bytes());
    b.extend_from_slice(&payload[..n]);
    let crc = CRC32.checksum(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    assert_eq!(b.len(), HEADER_LEN + n + 4);
    b
}

fn coefficients() -> impl Strategy<Value = Coefficients> {
    (
        (
            value(MAX_KP),
            value(MAX_KI),
            value(MAX_COMP_GAIN),
            value(RATED_VBUS_MAX),
        ),
        (
            value(RATED_I_MAX),
            value(RATED_VBUS_MAX),
            value(RATED_VBUS_MAX),
        ),
        (value(1.0), any::<u8>(), proptest::option::of(value(10.0))),
    )
        .prop_map(
            |((kp, ki, comp_gain, u_max), (i_max, vbus_min, vbus_max), (r, window, edge))| {
                let mut c = Coefficients::default();
                c.pi.kp = kp;
                c.pi.ki = ki;
                c.pi.comp_gain = comp_gain;
                c.pi.u_max = u_max;
                c.limits.i_max = i_max;
                c.limits.vbus_min = vbus_min;
                c.limits.vbus_max = vbus_max;
                c.motor.r = r;
                c.estimator = match edge {
                    Some(timeout_s) => Estimator::EdgeTiming { timeout_s },
                    None => Estimator::MovingAverage { window },
                };
                c
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn values_outside_the_ratings_are_refused_by_encode_and_decode(c in coefficients()) {
        let mut buf = [0u8; MAX_BLOB_LEN];
        let encoded = blob::encode(&c, &mut buf).map(<[u8]>::to_vec);
        let decoded = blob::decode(&forged(&c));
        if allowed(&c) {
            let bytes = encoded.unwrap();
            prop_assert_eq!(blob::decode(&bytes).unwrap(), c.clone());
            prop_assert_eq!(decoded.unwrap(), c);
        } else {
            prop_assert!(matches!(encoded, Err(BlobError::Invalid(_))), "{:?}", encoded);
            prop_assert!(matches!(decoded, Err(BlobError::Invalid(_))), "{:?}", decoded);
        }
    }
}

#[test]
fn the_values_of_a_hostile_blob_are_refused() {
    let mut c = Coefficients::default();
    c.limits.i_max = 1e30;
    c.limits.vbus_min = -1e30;
    c.limits.vbus_max = 1e30;
    c.pi.kp = -1.0;
    assert!(matches!(
        blob::decode(&forged(&c)),
        Err(BlobError::Invalid(_))
    ));
    let mut c = Coefficients::default();
    c.pi.u_max = 1e30;
    assert!(matches!(
        blob::decode(&forged(&c)),
        Err(BlobError::Invalid(_))
    ));
}
