//! The wire format: round trips for every message, strict decoding of bad input.

use proptest::prelude::*;
use slipstream::msg::*;

fn header() -> impl Strategy<Value = Header> {
    (any::<u64>(), any::<u64>(), any::<u64>()).prop_map(|(seq, stamp_sim_ns, stamp_pub_ns)| Header {
        seq,
        stamp_sim_ns,
        stamp_pub_ns,
    })
}
fn v3() -> impl Strategy<Value = [f64; 3]> {
    [-1e6f64..1e6, -1e6f64..1e6, -1e6f64..1e6]
}
fn unit() -> impl Strategy<Value = f32> {
    0.0f32..=1.0
}
fn class() -> impl Strategy<Value = ObjectClass> {
    prop_oneof![Just(ObjectClass::Unknown), Just(ObjectClass::Car), Just(ObjectClass::Van), Just(ObjectClass::Truck)]
}
fn bbox() -> impl Strategy<Value = BoundingBox2d> {
    (0f32..2000., 0f32..2000., 0f32..2000., 0f32..2000.).prop_map(|(a, b, c, d)| BoundingBox2d {
        u_min_px: a,
        v_min_px: b,
        u_max_px: c,
        v_max_px: d,
    })
}
fn control() -> impl Strategy<Value = ControlCommand> {
    let opt = || proptest::option::of(any::<u64>());
    (unit(), unit(), -1.0f32..=1.0, opt(), opt()).prop_map(|(throttle, brake, steer, answers_step, perception)| {
        ControlCommand { throttle, brake, steer, answers_step, perception_stamp_pub_ns: perception }
    })
}
fn state() -> impl Strategy<Value = VehicleState> {
    let timing = proptest::option::of((any::<u64>(), any::<u64>()))
        .prop_map(|t| t.map(|(c, a)| ControlTiming { command_stamp_pub_ns: c, applied_ns: a }));
    (any::<u64>(), v3(), -4f64..4., v3(), v3(), -2f64..2., 0f64..80., -1i32..8, control(), timing).prop_map(
        |(step, p, yaw, v, a, yr, speed, lane, applied, control_timing)| VehicleState {
            step,
            position_in_world_m: p,
            yaw_in_world_rad: yaw,
            pitch_rad: 0.01,
            roll_rad: -0.02,
            velocity_in_world_mps: v,
            acceleration_in_body_mps2: a,
            yaw_rate_radps: yr,
            speed_mps: speed,
            lane,
            applied,
            control_timing,
        },
    )
}
fn frame() -> impl Strategy<Value = CameraFrame> {
    prop_oneof![
        (1u32..8, 1u32..8).prop_flat_map(|(w, h)| proptest::collection::vec(any::<u8>(), (w * h * 3) as usize)
            .prop_map(move |data| CameraFrame { width: w, height: h, encoding: ImageEncoding::Rgb8, data })),
        proptest::collection::vec(any::<u8>(), 0..64).prop_map(|data| CameraFrame {
            width: 640,
            height: 480,
            encoding: ImageEncoding::Jpeg,
            data
        }),
    ]
}
fn gt_object() -> impl Strategy<Value = GroundTruthObject> {
    (any::<u32>(), class(), v3(), -1i32..5, v3(), v3(), v3(), v3(), proptest::option::of(bbox()), unit()).prop_map(
        |(id, class, size, lane, pw, vw, pe, ve, bbox, vis)| GroundTruthObject {
            id,
            class,
            size_m: size,
            lane,
            position_in_world_m: pw,
            yaw_in_world_rad: 0.1,
            velocity_in_world_mps: vw,
            position_in_ego_m: pe,
            yaw_in_ego_rad: -0.1,
            velocity_in_ego_mps: ve,
            bbox,
            visible_fraction: vis,
        },
    )
}
fn detection() -> impl Strategy<Value = Detection> {
    (any::<u32>(), class(), bbox(), unit(), 0f64..200., -10f64..10., -40f64..40.).prop_map(
        |(track_id, class, bbox, confidence, d, l, r)| Detection {
            track_id,
            class,
            bbox,
            confidence,
            distance_m: d,
            lateral_offset_m: l,
            relative_speed_mps: r,
        },
    )
}
fn event() -> impl Strategy<Value = SimEvent> {
    prop_oneof![
        (".{0,20}", any::<u64>()).prop_map(|(name, seed)| SimEventKind::ScenarioStart { name, seed }),
        (".{0,20}", any::<bool>()).prop_map(|(reason, success)| SimEventKind::ScenarioEnd { reason, success }),
        (any::<u32>(), 0f64..50.).prop_map(|(other_id, r)| SimEventKind::Collision { other_id, relative_speed_mps: r }),
        proptest::collection::vec("[a-z-]{1,12}", 0..4).prop_map(|late| SimEventKind::ControlTimeout { late }),
    ]
    .prop_map(|kind| SimEvent { kind })
}
fn acc_status() -> impl Strategy<Value = AccStatus> {
    let mode = prop_oneof![
        Just(AccMode::Off),
        Just(AccMode::Speed),
        Just(AccMode::Follow),
        Just(AccMode::Stale),
        Just(AccMode::Emergency)
    ];
    let warning = prop_oneof![
        Just(AccWarning::ForwardCollision),
        Just(AccWarning::StaleSpeed),
        Just(AccWarning::StalePerception),
        Just(AccWarning::PerceptionLost)
    ];
    let lead = (any::<u32>(), 0f64..200., 0f64..200., -30f64..30., proptest::option::of(0f64..100.)).prop_map(
        |(id, gap_m, desired_gap_m, relative_speed_mps, ttc_s)| LeadInfo {
            id,
            gap_m,
            desired_gap_m,
            relative_speed_mps,
            ttc_s,
        },
    );
    (mode, 0f64..60., 0.5f64..3., -9f64..3., proptest::option::of(lead), proptest::collection::vec(warning, 0..4))
        .prop_map(|(mode, set_speed_mps, time_gap_s, target_accel_mps2, lead, warnings)| AccStatus {
            mode,
            set_speed_mps,
            time_gap_s,
            target_accel_mps2,
            lead,
            warnings,
        })
}

/// Encodes, decodes, compares; then every strict prefix must fail, never panic.
fn check_round_trip<M>(h: Header, m: M)
where
    M: Message + serde::de::DeserializeOwned + PartialEq + Clone,
{
    let bytes = encode(&h, &m);
    let back = decode::<M>(&bytes).expect("decodes");
    assert_eq!(back.header, h);
    assert_eq!(back.msg, m);
    for cut in 0..bytes.len() {
        assert!(decode::<M>(&bytes[..cut]).is_err(), "prefix of {cut}/{} bytes decoded", bytes.len());
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert_eq!(decode::<M>(&longer), Err(DecodeError::TrailingBytes { expected: M::KIND.name(), count: 1 }));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn speed_round_trips(h in header(), v in -100f64..100.) { check_round_trip(h, Speed { speed_mps: v }) }
    #[test]
    fn state_round_trips(h in header(), s in state()) { check_round_trip(h, s) }
    #[test]
    fn control_round_trips(h in header(), c in control()) { check_round_trip(h, c) }
    #[test]
    fn frame_round_trips(h in header(), f in frame()) { check_round_trip(h, f) }
    #[test]
    fn info_round_trips(h in header(), w in 1u32..4000, ht in 1u32..3000, f in 1f64..5000.) {
        check_round_trip(h, CameraInfo {
            width: w, height: ht, fx_px: f, fy_px: f, cx_px: w as f64 / 2., cy_px: ht as f64 / 2.,
            horizontal_fov_rad: 1.0, mount_position_in_ego_m: [1.5, 0., 1.4], mount_roll_pitch_yaw_rad: [0., 0.05, 0.],
            rate_hz: 20., encoding: ImageEncoding::Jpeg,
        })
    }
    #[test]
    fn ground_truth_round_trips(h in header(), step in any::<u64>(), objects in proptest::collection::vec(gt_object(), 0..5)) {
        check_round_trip(h, GroundTruthObjects { step, objects })
    }
    #[test]
    fn detections_round_trip(h in header(), seq in any::<u64>(), t in any::<u64>(), d in proptest::collection::vec(detection(), 0..5)) {
        check_round_trip(h, Detections { frame_seq: seq, frame_stamp_pub_ns: t, detections: d })
    }
    #[test]
    fn clock_round_trips(h in header(), step in any::<u64>(), rtf in 0f32..100., m in prop_oneof![Just(SimMode::Realtime), Just(SimMode::Fast), Just(SimMode::Lockstep)]) {
        check_round_trip(h, SimClock { step, real_time_factor: rtf, mode: m, physics_hz: 100. })
    }
    #[test]
    fn event_round_trips(h in header(), e in event()) { check_round_trip(h, e) }
    #[test]
    fn acc_status_round_trips(h in header(), s in acc_status()) { check_round_trip(h, s) }
    #[test]
    fn acc_command_round_trips(h in header(), e in proptest::option::of(any::<bool>()), v in proptest::option::of(0f64..60.), g in proptest::option::of(0.5f64..3.)) {
        check_round_trip(h, AccCommand { enable: e, set_speed_mps: v, time_gap_s: g })
    }

    /// Random bytes never panic any decoder; with a valid preamble they still mostly fail.
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..256), kind in 1u8..=11) {
        let mut with_preamble = vec![WIRE_VERSION, kind];
        with_preamble.extend_from_slice(&bytes);
        for input in [&bytes[..], &with_preamble[..]] {
            let _ = decode::<Speed>(input);
            let _ = decode::<VehicleState>(input);
            let _ = decode::<ControlCommand>(input);
            let _ = decode::<CameraFrame>(input);
            let _ = decode::<CameraFrameRef>(input);
            let _ = decode::<CameraInfo>(input);
            let _ = decode::<GroundTruthObjects>(input);
            let _ = decode::<Detections>(input);
            let _ = decode::<SimClock>(input);
            let _ = decode::<SimEvent>(input);
            let _ = decode::<AccStatus>(input);
            let _ = decode::<AccCommand>(input);
        }
    }
}

#[test]
fn every_example_decodes_and_every_truncation_fails() {
    for (kind, bytes) in examples() {
        assert_eq!(bytes[0], WIRE_VERSION);
        assert_eq!(bytes[1], kind as u8);
        for cut in 0..bytes.len() {
            let r = match kind {
                MessageKind::Speed => decode::<Speed>(&bytes[..cut]).map(|_| ()),
                MessageKind::VehicleState => decode::<VehicleState>(&bytes[..cut]).map(|_| ()),
                MessageKind::ControlCommand => decode::<ControlCommand>(&bytes[..cut]).map(|_| ()),
                MessageKind::CameraFrame => decode::<CameraFrameRef>(&bytes[..cut]).map(|_| ()),
                MessageKind::CameraInfo => decode::<CameraInfo>(&bytes[..cut]).map(|_| ()),
                MessageKind::GroundTruthObjects => decode::<GroundTruthObjects>(&bytes[..cut]).map(|_| ()),
                MessageKind::Detections => decode::<Detections>(&bytes[..cut]).map(|_| ()),
                MessageKind::SimClock => decode::<SimClock>(&bytes[..cut]).map(|_| ()),
                MessageKind::SimEvent => decode::<SimEvent>(&bytes[..cut]).map(|_| ()),
                MessageKind::AccStatus => decode::<AccStatus>(&bytes[..cut]).map(|_| ()),
                MessageKind::AccCommand => decode::<AccCommand>(&bytes[..cut]).map(|_| ()),
            };
            assert!(r.is_err(), "{kind:?}: a {cut}-byte prefix decoded");
        }
    }
}

#[test]
fn errors_say_what_was_wrong() {
    let h = Header { seq: 1, stamp_sim_ns: 2, stamp_pub_ns: 3 };
    let good = encode(&h, &Speed { speed_mps: 1.0 });

    assert_eq!(decode::<Speed>(&[]), Err(DecodeError::Empty { expected: "Speed" }));

    let mut other = good.clone();
    other[0] = WIRE_VERSION + 1;
    let e = decode::<Speed>(&other).unwrap_err();
    assert_eq!(e, DecodeError::UnknownVersion { expected: "Speed", found: WIRE_VERSION + 1 });
    assert!(e.to_string().contains(&format!("unknown wire version {}", WIRE_VERSION + 1)), "{e}");
    other[0] = 1;
    assert_eq!(
        decode::<Speed>(&other),
        Err(DecodeError::UnknownVersion { expected: "Speed", found: 1 }),
        "version 1 (before the loop trace) is refused"
    );

    let e = decode::<ControlCommand>(&good).unwrap_err();
    assert_eq!(e, DecodeError::WrongKind { expected: "ControlCommand", found: "Speed" });

    let mut unknown = good.clone();
    unknown[1] = 200;
    assert_eq!(decode::<Speed>(&unknown), Err(DecodeError::UnknownKind { expected: "Speed", found: 200 }));

    let e = decode::<Speed>(&good[..good.len() - 1]).unwrap_err();
    assert!(matches!(e, DecodeError::Truncated { part: "body", .. }), "{e:?}");

    // A bad enum tag: SimClock's mode is the last byte.
    let clock = encode(&h, &SimClock { step: 1, real_time_factor: 1.0, mode: SimMode::Fast, physics_hz: 100.0 });
    let mut bad = clock.clone();
    let mode_at = bad.len() - 9; // mode byte, then physics_hz (8 bytes)
    bad[mode_at] = 9;
    let e = decode::<SimClock>(&bad).unwrap_err();
    assert!(matches!(&e, DecodeError::Malformed { reason, .. } if reason.contains("enum")), "{e:?}");

    // Content checks: a frame whose pixel count does not match its size, a throttle above 1.
    let frame = encode(&h, &CameraFrame { width: 2, height: 2, encoding: ImageEncoding::Rgb8, data: vec![0; 11] });
    assert!(matches!(decode::<CameraFrameRef>(&frame), Err(DecodeError::Invalid { .. })));
    let over = encode(&h, &ControlCommand { throttle: 1.5, ..ControlCommand::NEUTRAL });
    let e = decode::<ControlCommand>(&over).unwrap_err();
    assert!(e.to_string().contains("throttle 1.5"), "{e}");
}

#[test]
fn frame_prefix_plus_pixels_is_the_encoded_frame() {
    let h = Header { seq: 42, stamp_sim_ns: 10_000_000, stamp_pub_ns: 99 };
    let data: Vec<u8> = (0..(4 * 3 * 3)).map(|i| i as u8).collect();
    let frame = CameraFrame { width: 4, height: 3, encoding: ImageEncoding::Rgb8, data: data.clone() };
    let mut assembled = frame_prefix(&h, 4, 3, ImageEncoding::Rgb8, data.len());
    assembled.extend_from_slice(&data);
    assert_eq!(assembled, encode(&h, &frame));
    // The borrowed decode points into the payload: no copy of the pixels.
    let view = decode::<CameraFrameRef>(&assembled).unwrap();
    let at = assembled.len() - data.len();
    assert_eq!(view.msg.data.as_ptr(), assembled[at..].as_ptr());
}

/// docs/wire-format.md quotes every example byte for byte: the doc cannot drift from the code.
#[test]
fn the_wire_format_doc_quotes_every_example() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/wire-format.md")).unwrap();
    for (kind, bytes) in examples() {
        let hex = hex_lines(&bytes);
        assert!(doc.contains(&hex), "docs/wire-format.md lacks the {} example:\n{hex}\n", kind.name());
    }
}
