//! The wire format: round trips for every message, strict decoding of bad input.

use slipstream::msg::*;
use slipstream::sim::SimRng;

/// Cases per message type: each from its own seed, so a failure names the case to rerun.
const CASES: u64 = 64;

/// Random valid messages from a seeded generator (the simulator's own, so runs repeat).
struct Gen(SimRng);

impl Gen {
    fn new(seed: u64) -> Self {
        Gen(SimRng::new(seed))
    }
    fn u64(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn u32(&mut self) -> u32 {
        self.0.next_u64() as u32
    }
    fn f64(&mut self, lo: f64, hi: f64) -> f64 {
        self.0.range(lo, hi)
    }
    fn f32(&mut self, lo: f64, hi: f64) -> f32 {
        self.0.range(lo, hi) as f32
    }
    fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + self.0.below((hi - lo) as u64) as i64
    }
    fn bool(&mut self) -> bool {
        self.0.below(2) == 1
    }
    fn pick<T: Clone>(&mut self, from: &[T]) -> T {
        from[self.0.below(from.len() as u64) as usize].clone()
    }
    fn opt<T>(&mut self, f: impl FnOnce(&mut Self) -> T) -> Option<T> {
        self.bool().then(|| f(self))
    }
    fn vec<T>(&mut self, max_len: u64, mut f: impl FnMut(&mut Self) -> T) -> Vec<T> {
        let n = self.0.below(max_len + 1);
        (0..n).map(|_| f(self)).collect()
    }
    fn bytes(&mut self, len: usize) -> Vec<u8> {
        (0..len).map(|_| self.0.next_u64() as u8).collect()
    }
    /// Any text, multi-byte characters included.
    fn text(&mut self, max_len: u64) -> String {
        self.vec(max_len, |g| g.pick(&['a', 'Z', '-', ' ', '0', 'é', '→', '漢', '\n'])).into_iter().collect()
    }
    fn v3(&mut self) -> [f64; 3] {
        [self.f64(-1e6, 1e6), self.f64(-1e6, 1e6), self.f64(-1e6, 1e6)]
    }
    fn header(&mut self) -> Header {
        Header { seq: self.u64(), stamp_sim_ns: self.u64(), stamp_pub_ns: self.u64() }
    }
    fn class(&mut self) -> ObjectClass {
        self.pick(&[ObjectClass::Unknown, ObjectClass::Car, ObjectClass::Van, ObjectClass::Truck])
    }
    fn bbox(&mut self) -> BoundingBox2d {
        BoundingBox2d {
            u_min_px: self.f32(0.0, 2000.0),
            v_min_px: self.f32(0.0, 2000.0),
            u_max_px: self.f32(0.0, 2000.0),
            v_max_px: self.f32(0.0, 2000.0),
        }
    }
    fn control(&mut self) -> ControlCommand {
        ControlCommand {
            throttle: self.f32(0.0, 1.0),
            brake: self.f32(0.0, 1.0),
            steer: self.f32(-1.0, 1.0),
            answers_step: self.opt(Gen::u64),
            perception_stamp_pub_ns: self.opt(Gen::u64),
        }
    }
    fn state(&mut self) -> VehicleState {
        VehicleState {
            step: self.u64(),
            position_in_world_m: self.v3(),
            yaw_in_world_rad: self.f64(-4.0, 4.0),
            pitch_rad: 0.01,
            roll_rad: -0.02,
            velocity_in_world_mps: self.v3(),
            acceleration_in_body_mps2: self.v3(),
            yaw_rate_radps: self.f64(-2.0, 2.0),
            speed_mps: self.f64(0.0, 80.0),
            lane: self.int(-1, 8) as i32,
            applied: self.control(),
            control_timing: self.opt(|g| ControlTiming { command_stamp_pub_ns: g.u64(), applied_ns: g.u64() }),
        }
    }
    fn frame(&mut self) -> CameraFrame {
        if self.bool() {
            let (w, h) = (self.int(1, 8) as u32, self.int(1, 8) as u32);
            CameraFrame { width: w, height: h, encoding: ImageEncoding::Rgb8, data: self.bytes((w * h * 3) as usize) }
        } else {
            let len = self.int(0, 64) as usize;
            CameraFrame { width: 640, height: 480, encoding: ImageEncoding::Jpeg, data: self.bytes(len) }
        }
    }
    fn gt_object(&mut self) -> GroundTruthObject {
        GroundTruthObject {
            id: self.u32(),
            class: self.class(),
            size_m: self.v3(),
            lane: self.int(-1, 5) as i32,
            position_in_world_m: self.v3(),
            yaw_in_world_rad: 0.1,
            velocity_in_world_mps: self.v3(),
            position_in_ego_m: self.v3(),
            yaw_in_ego_rad: -0.1,
            velocity_in_ego_mps: self.v3(),
            bbox: self.opt(Gen::bbox),
            visible_fraction: self.f32(0.0, 1.0),
            brake_lights: self.bool(),
        }
    }
    fn detection(&mut self) -> Detection {
        Detection {
            track_id: self.u32(),
            class: self.class(),
            bbox: self.bbox(),
            confidence: self.f32(0.0, 1.0),
            distance_m: self.f64(0.0, 200.0),
            lateral_offset_m: self.f64(-10.0, 10.0),
            relative_speed_mps: self.f64(-40.0, 40.0),
            distance_sigma_m: self.f64(0.0, 5.0),
            relative_speed_sigma_mps: self.f64(0.0, 30.0),
            brake_lights: self.bool(),
        }
    }
    fn event(&mut self) -> SimEvent {
        let kind = match self.int(0, 4) {
            0 => SimEventKind::ScenarioStart { name: self.text(20), seed: self.u64() },
            1 => SimEventKind::ScenarioEnd { reason: self.text(20), success: self.bool() },
            2 => SimEventKind::Collision { other_id: self.u32(), relative_speed_mps: self.f64(0.0, 50.0) },
            _ => SimEventKind::ControlTimeout { late: self.vec(3, |g| g.text(12)) },
        };
        SimEvent { kind }
    }
    fn acc_status(&mut self) -> AccStatus {
        let modes = [AccMode::Off, AccMode::Speed, AccMode::Follow, AccMode::Stale, AccMode::Emergency];
        let warnings = [
            AccWarning::ForwardCollision,
            AccWarning::StaleSpeed,
            AccWarning::StalePerception,
            AccWarning::PerceptionLost,
        ];
        AccStatus {
            mode: self.pick(&modes),
            set_speed_mps: self.f64(0.0, 60.0),
            time_gap_s: self.f64(0.5, 3.0),
            target_accel_mps2: self.f64(-9.0, 3.0),
            lead: self.opt(|g| LeadInfo {
                id: g.u32(),
                gap_m: g.f64(0.0, 200.0),
                desired_gap_m: g.f64(0.0, 200.0),
                relative_speed_mps: g.f64(-30.0, 30.0),
                ttc_s: g.opt(|g| g.f64(0.0, 100.0)),
            }),
            warnings: self.vec(3, |g| g.pick(&warnings)),
        }
    }
}

/// Runs `check` on CASES messages made by `make`, each case from its own seed.
fn for_cases<M>(salt: u64, make: impl Fn(&mut Gen) -> M, check: impl Fn(Header, M)) {
    for case in 0..CASES {
        let mut g = Gen::new(salt * 1_000 + case);
        let h = g.header();
        check(h, make(&mut g));
    }
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

#[test]
fn speed_round_trips() {
    for_cases(1, |g| Speed { speed_mps: g.f64(-100.0, 100.0) }, check_round_trip);
}

#[test]
fn state_round_trips() {
    for_cases(2, Gen::state, check_round_trip);
}

#[test]
fn control_round_trips() {
    for_cases(3, Gen::control, check_round_trip);
}

#[test]
fn frame_round_trips() {
    for_cases(4, Gen::frame, check_round_trip);
}

#[test]
fn info_round_trips() {
    let info = |g: &mut Gen| {
        let (w, h, f) = (g.int(1, 4000) as u32, g.int(1, 3000) as u32, g.f64(1.0, 5000.0));
        CameraInfo {
            width: w,
            height: h,
            fx_px: f,
            fy_px: f,
            cx_px: w as f64 / 2.,
            cy_px: h as f64 / 2.,
            horizontal_fov_rad: 1.0,
            mount_position_in_ego_m: [1.5, 0., 1.4],
            mount_roll_pitch_yaw_rad: [0., 0.05, 0.],
            rate_hz: 20.,
            encoding: ImageEncoding::Jpeg,
        }
    };
    for_cases(5, info, check_round_trip);
}

#[test]
fn ground_truth_round_trips() {
    for_cases(6, |g| GroundTruthObjects { step: g.u64(), objects: g.vec(4, Gen::gt_object) }, check_round_trip);
}

#[test]
fn detections_round_trip() {
    let detections = |g: &mut Gen| Detections {
        frame_seq: g.u64(),
        frame_stamp_pub_ns: g.u64(),
        detections: g.vec(4, Gen::detection),
    };
    for_cases(7, detections, check_round_trip);
}

#[test]
fn clock_round_trips() {
    let clock = |g: &mut Gen| SimClock {
        step: g.u64(),
        real_time_factor: g.f32(0.0, 100.0),
        mode: g.pick(&[SimMode::Realtime, SimMode::Fast, SimMode::Lockstep]),
        physics_hz: 100.,
    };
    for_cases(8, clock, check_round_trip);
}

#[test]
fn event_round_trips() {
    for_cases(9, Gen::event, check_round_trip);
}

#[test]
fn acc_status_round_trips() {
    for_cases(10, Gen::acc_status, check_round_trip);
}

#[test]
fn acc_command_round_trips() {
    let command = |g: &mut Gen| AccCommand {
        enable: g.opt(Gen::bool),
        set_speed_mps: g.opt(|g| g.f64(0.0, 60.0)),
        time_gap_s: g.opt(|g| g.f64(0.5, 3.0)),
    };
    for_cases(11, command, check_round_trip);
}

/// Random bytes never panic any decoder, with or without a valid preamble.
#[test]
fn random_bytes_never_panic() {
    let mut g = Gen::new(12);
    for _ in 0..2_000 {
        let len = g.int(0, 256) as usize;
        let bytes = g.bytes(len);
        let mut with_preamble = vec![WIRE_VERSION, g.int(1, 14) as u8];
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
            let _ = decode::<RoadSpec>(input);
            let _ = decode::<slipstream::msg::EgoInfo>(input);
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
                MessageKind::RoadMap => decode::<RoadSpec>(&bytes[..cut]).map(|_| ()),
                MessageKind::EgoInfo => decode::<slipstream::msg::EgoInfo>(&bytes[..cut]).map(|_| ()),
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
    // A detection whose relative speed has a negative standard deviation.
    let detection = Detection {
        track_id: 4,
        class: ObjectClass::Car,
        bbox: BoundingBox2d { u_min_px: 300.0, v_min_px: 220.0, u_max_px: 340.0, v_max_px: 250.0 },
        confidence: 0.9,
        distance_m: 43.6,
        lateral_offset_m: 0.1,
        relative_speed_mps: -1.0,
        distance_sigma_m: 0.2,
        relative_speed_sigma_mps: -0.5,
        brake_lights: false,
    };
    let detections = Detections { frame_seq: 1, frame_stamp_pub_ns: 0, detections: vec![detection] };
    let e = decode::<Detections>(&encode(&h, &detections)).unwrap_err();
    assert!(e.to_string().contains("standard deviations must be 0 or more"), "{e}");
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

/// One version everywhere the doc states it: its title, the envelope table a reader is
/// written from, every encoding schema, the first byte of every worked example, the worked
/// example's byte table and the decoding rules.
#[test]
fn the_wire_format_doc_states_one_version_everywhere() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/wire-format.md")).unwrap();
    let v = slipstream::msg::WIRE_VERSION;
    assert!(doc.starts_with(&format!("# slipstream wire format (version {v})\n")), "the title");
    let envelope = doc.lines().find(|l| l.starts_with("| 0 | 1 | version |")).expect("the envelope's version row");
    assert!(envelope.contains(&format!("`0x{v:02x}`")), "the envelope table says {envelope}");
    let schemas: Vec<&str> = doc.split("slipstream/").skip(1).filter_map(|s| s.split(['|', '`', ' ']).next()).collect();
    assert!(schemas.len() >= 14, "{schemas:?}");
    for schema in schemas.iter().filter(|s| s.contains("/v")) {
        assert!(schema.ends_with(&format!("/v{v}")), "encoding schema {schema}");
    }
    for (kind, bytes) in examples() {
        assert_eq!(bytes[0], v, "{} example", kind.name());
    }
    // The worked example's byte table and the decoding rules say it too.
    assert!(doc.contains(&format!("| `{v:02x}` | version | {v} |")), "the worked example's version row");
    let refused: Vec<&str> = doc.match_indices("a version other than ").map(|(i, m)| &doc[i + m.len()..]).collect();
    assert!(!refused.is_empty(), "the decoding rules name the version refused");
    for rest in refused {
        assert!(rest.starts_with(&format!("{v};")), "the decoding rules refuse a version other than {rest:.3}");
    }
}

/// Every decoder and config parser takes 100,000 (parsers 5,000) mutated valid inputs without
/// a panic, and the mutations reach both sides: some inputs accepted, most rejected
/// (`slipstream fuzz --count 10000000` is the long run, docs/performance.md).
#[test]
fn mutated_inputs_are_accepted_or_rejected_never_a_panic() {
    // Seconds of one core at full load: not beside the loop tests, whose timing it would squeeze.
    let _serial = crate::common::serial();
    let reports = slipstream::tools::fuzz::run(100_000, 5_000, 7);
    assert!(reports.len() >= 15, "{} targets", reports.len());
    for r in &reports {
        assert_eq!(r.panics, 0, "{}: {:?}", r.target, r.first_panic);
        assert!(
            r.accepted > 0 && r.rejected > r.accepted,
            "{}: {} accepted, {} rejected",
            r.target,
            r.accepted,
            r.rejected
        );
    }
    // Seeded: the same seed gives the same inputs, so the same verdicts.
    let again = slipstream::tools::fuzz::run(1_000, 100, 7);
    let first = slipstream::tools::fuzz::run(1_000, 100, 7);
    let verdicts =
        |v: &[slipstream::tools::fuzz::TargetReport]| v.iter().map(|r| (r.accepted, r.rejected)).collect::<Vec<_>>();
    assert_eq!(verdicts(&again), verdicts(&first));
}
