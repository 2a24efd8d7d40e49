use super::*;
use crate::scenario::Scenario;
use crate::world::World;
use slipstream_contract::msg::ImageEncoding;

fn camera() -> CameraInfo {
    CameraInfo::pinhole(320, 240, 60f64.to_radians(), [1.6, 0.0, 1.35], [0.0, 0.03, 0.0], 20.0, ImageEncoding::Rgb8)
}

fn world(traffic: &str) -> World {
    let text = format!(
        "{{ name: 't', duration_s: 10, variation: {{ gap_m: 0, speed_mps: 0 }}, ego: {{ lane: 1, speed_mps: 0 }}, traffic: [{traffic}] }}"
    );
    World::new(Scenario::parse(&text, "test").unwrap(), 1, 100)
}

fn render(world: &World) -> (Vec<u8>, Vec<ObjectVisibility>) {
    let mut r = Renderer::new(&camera(), 0.0, &mut SimRng::new(1));
    let mut rgb = vec![0; r.frame_len()];
    let vis = r.render(world.road(), world.ego(), world.vehicles(), FrameLook::PLAIN, &mut rgb);
    (rgb, vis)
}

#[test]
fn a_vehicle_ahead_is_drawn_inside_its_box_and_differs_from_the_empty_road() {
    let (empty, none) = render(&world(""));
    assert!(none.is_empty());
    let (with_car, vis) = render(&world("{ lane: 1, gap_m: 15, speed_mps: 0, color: [200, 30, 35] }"));
    let v = vis[0];
    let b = v.bbox.expect("the car ahead is in the image");
    // Centred horizontally (same lane), below the horizon, a plausible size at ~17 m.
    let centre_u = (b.u_min_px + b.u_max_px) / 2.0;
    assert!((centre_u - 160.0).abs() < 10.0, "{b:?}");
    assert!(b.u_max_px - b.u_min_px > 20.0 && b.u_max_px - b.u_min_px < 80.0, "{b:?}");
    assert!(v.visible_fraction > 0.99, "nothing hides it: {v:?}");
    let (mut inside, mut differ) = (0, 0);
    for y in b.v_min_px as usize..b.v_max_px as usize {
        for x in b.u_min_px as usize..b.u_max_px as usize {
            let i = (y * 320 + x) * 3;
            inside += 1;
            if with_car[i..i + 3] != empty[i..i + 3] {
                differ += 1;
            }
        }
    }
    assert!(differ * 10 > inside * 7, "{differ} of {inside} pixels in the box changed");
    // Every changed pixel is the car's or its shadow's (ground layer, not part of the car; at
    // the shadow's edges a blend of it and the ground by one share in every channel).
    let shadow_blend = |x: &[u8], ground: &[u8]| {
        let share = |c: usize| (x[c] as f32 - ground[c] as f32) / (scene::SHADOW[c] as f32 - ground[c] as f32);
        (0..3).all(|c| (share(c) - share(0)).abs() <= 0.05 && (0.0..=1.0).contains(&share(c)))
    };
    let changed_not_shadow =
        with_car.chunks(3).zip(empty.chunks(3)).filter(|(x, y)| x != y && !shadow_blend(x, y)).count();
    assert_eq!(v.visible_px as usize, changed_not_shadow);
}

#[test]
fn a_vehicle_behind_another_is_partly_hidden_and_one_outside_the_view_has_no_box() {
    let (_, vis) = render(&world(
        "{ lane: 1, gap_m: 12, speed_mps: 0 }, { lane: 1, gap_m: 30, speed_mps: 0, class: 'truck' }, { lane: 0, gap_m: -20, speed_mps: 0 }",
    ));
    let (near, far, behind) = (vis[0], vis[1], vis[2]);
    assert!(near.visible_fraction > 0.99);
    assert!(far.visible_fraction > 0.05 && far.visible_fraction < 0.9, "the truck shows above the car: {far:?}");
    assert!(far.bbox.is_some());
    assert_eq!((behind.bbox, behind.visible_px), (None, 0));
}
