//! Scene-adaptive compute: each skip does what it says, is counted, can be
//! turned off, and keeps the output and the temporal state correct.

use deskstage::math::Vec3;
use deskstage::monitor::RgbImage;
use deskstage::subject::{Pose, State};
use gst::prelude::*;
use gst_check::Harness;
use lsydrelight_testkit::{
    element::{element, stat},
    person::{FACE_H, FACE_W, face_rgb, render_face, render_person},
    target,
    video::{FRAME, buffer, caps, frame_time, mean_abs_diff, rgb_caps, to_rgb},
};

fn harness_with(configure: impl FnOnce(&gst::Element)) -> (gst::Element, Harness, gst::Caps) {
    let e = element();
    // The skips are about the region relit, wherever it is: a fixed one here.
    e.set_property("face-tracking", false);
    configure(&e);
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    (e, h, c)
}

fn push(h: &mut Harness, c: &gst::Caps, img: &RgbImage, i: u64) -> RgbImage {
    h.push(buffer(img, c, frame_time(i), FRAME)).unwrap();
    to_rgb(&h.pull().unwrap(), c)
}

#[test]
fn a_still_scene_carries_the_relighting_between_network_runs() {
    let still = face_rgb();
    let moved = render_person(
        &State {
            pose: Pose {
                yaw: 0.2,
                ..Pose::default()
            },
            ..State::default()
        },
        Vec3::new(1.0, 1.0, 1.0),
        FACE_W,
        FACE_H,
    );
    let run = |interval: u32| {
        let (e, mut h, c) = harness_with(|e| e.set_property("reuse-interval", interval));
        let outs: Vec<RgbImage> = (0..6).map(|i| push(&mut h, &c, still, i)).collect();
        let after = push(&mut h, &c, &moved, 6);
        (e, outs, after)
    };
    let (reusing, outs_reused, after_reused) = run(3);
    let (computing, outs_full, after_full) = run(1);
    // Frames 1, 2, 4 and 5 carry the relighting of frames 0 and 3; the moved frame
    // runs the network.
    assert_eq!(stat(&reusing, "reused-interval"), 4);
    assert_eq!(stat(&reusing, "relit"), 3);
    assert_eq!(
        stat(&computing, "reused-interval"),
        0,
        "reuse-interval=1 always runs the network"
    );
    // The same frame, carried or recomputed: the same picture within a level.
    for (a, b) in outs_reused.iter().zip(&outs_full) {
        assert!(mean_abs_diff(a, b) < 0.5);
    }
    // The smoothing state advanced across the carried frames as if they had run.
    assert!(
        mean_abs_diff(&after_reused, &after_full) < 0.1,
        "the first changed frame after a still stretch: {}",
        mean_abs_diff(&after_reused, &after_full)
    );
}

#[test]
fn source_equal_to_target_passes_the_frame_through() {
    let white = target("studio");
    let (e, mut h, c) = harness_with(|e| e.set_property("target-location", &white));
    let mut mh = Harness::with_element(&e, Some("monitor_sink"), None);
    let shown = deskstage::io::read_png(std::path::Path::new(&white)).unwrap();
    mh.set_src_caps(rgb_caps(shown.width as u32, shown.height as u32, 30));
    let b = |i: u64| {
        buffer(
            &shown,
            &rgb_caps(shown.width as u32, shown.height as u32, 30),
            frame_time(i),
            FRAME,
        )
    };
    // The face frame goes in between: each sink pad holds one buffer until the
    // element takes it, and it takes monitor frames only for a face frame.
    mh.push(b(0)).unwrap();
    h.push(buffer(face_rgb(), &c, frame_time(0), FRAME))
        .unwrap();
    mh.push(b(1)).unwrap();
    let out = to_rgb(&h.pull().unwrap(), &c);
    assert_eq!(stat(&e, "skipped-same-light"), 1);
    assert_eq!(
        out,
        to_rgb(&buffer(face_rgb(), &c, frame_time(0), FRAME), &c),
        "passed through untouched"
    );

    // Without a monitor stream the source light is predicted from each frame, so it
    // can never be taken as the target's: every frame runs the network.
    let (e3, mut h3, c3) = harness_with(|e| {
        e.set_property("target-location", &white);
        e.set_property("same-light-tolerance", 1.0f64);
        // The same frame three times is a static scene; that skip is not under test.
        e.set_property("reuse-interval", 1u32);
    });
    for i in 0..3 {
        h3.push(buffer(face_rgb(), &c3, frame_time(i), FRAME))
            .unwrap();
        h3.pull().unwrap();
    }
    assert_eq!(stat(&e3, "skipped-same-light"), 0);
    assert_eq!(stat(&e3, "relit"), 3);

    let (e2, mut h2, c2) = harness_with(|e| {
        e.set_property("target-location", &white);
        e.set_property("skip-same-light", false);
    });
    let mut mh2 = Harness::with_element(&e2, Some("monitor_sink"), None);
    mh2.set_src_caps(rgb_caps(shown.width as u32, shown.height as u32, 30));
    mh2.push(b(0)).unwrap();
    h2.push(buffer(face_rgb(), &c2, frame_time(0), FRAME))
        .unwrap();
    mh2.push(b(1)).unwrap();
    h2.pull().unwrap();
    assert_eq!(stat(&e2, "skipped-same-light"), 0);
    assert_eq!(stat(&e2, "relit"), 1);
}

#[test]
fn nobody_there_means_no_inference_and_a_fresh_start() {
    let away = render_person(
        &State {
            pose: Pose {
                present: false,
                ..Pose::default()
            },
            ..State::default()
        },
        Vec3::new(1.0, 1.0, 1.0),
        FACE_W,
        FACE_H,
    );
    let (e, mut h, c) = harness_with(|e| e.set_property("reuse-interval", 1u32));
    let mut side = Harness::with_element(&e, None, Some("monitor_src"));
    push(&mut h, &c, face_rgb(), 0);
    push(&mut h, &c, face_rgb(), 1);
    for i in 2..5 {
        let out = push(&mut h, &c, &away, i);
        assert_eq!(
            out,
            to_rgb(&buffer(&away, &c, frame_time(i), FRAME), &c),
            "the empty desk passes through"
        );
    }
    assert_eq!(stat(&e, "skipped-absent"), 3);
    assert_eq!(stat(&e, "relit"), 2);
    // The predicted monitor keeps time: a picture for each relit frame, a gap for each
    // frame with nobody there.
    for i in 0..2 {
        assert_eq!(side.pull().unwrap().pts(), Some(frame_time(i)));
    }
    let mut gaps = Vec::new();
    while gaps.len() < 3 {
        let event = side.pull_event().expect("the gaps reach monitor_src");
        if let gst::EventView::Gap(g) = event.view() {
            gaps.push(g.get().0);
        }
    }
    assert_eq!(gaps, (2..5).map(frame_time).collect::<Vec<_>>());
    // Back: relit as a first frame would be, with no state from before the absence.
    let back = push(&mut h, &c, face_rgb(), 5);
    let (_, mut fresh, fc) = harness_with(|_| {});
    let first = push(&mut fresh, &fc, face_rgb(), 0);
    assert!(mean_abs_diff(&back, &first) < 0.05);

    let (e2, mut h2, c2) = harness_with(|e| e.set_property("skip-absent", false));
    push(&mut h2, &c2, &away, 0);
    assert_eq!(stat(&e2, "skipped-absent"), 0);
    assert_eq!(stat(&e2, "relit"), 1);
}

#[test]
fn late_frames_reuse_the_relighting_and_say_so() {
    let (e, mut h, c) = harness_with(|e| e.set_property("reuse-interval", 1u32));
    let bus = gst::Bus::new();
    e.set_bus(Some(&bus));
    push(&mut h, &c, face_rgb(), 0);
    let denoised = e
        .property::<gst::Structure>("stats")
        .get::<f64>("denoise-seconds")
        .unwrap();
    assert!(denoised > 0.0, "the relit frame is denoised");
    // Downstream reports being a second behind: frames before then are too late to matter.
    let qos = gst::event::Qos::new(
        gst::QOSType::Underflow,
        0.5,
        1_000_000_000,
        Some(frame_time(1)),
    );
    assert!(h.push_upstream_event(qos));
    let dim = render_face(Vec3::new(0.3, 0.3, 0.3));
    for i in 1..4 {
        push(&mut h, &c, &dim, i);
    }
    assert_eq!(
        stat(&e, "qos-reused"),
        3,
        "late frames reuse the last relighting"
    );
    assert_eq!(stat(&e, "relit"), 1);
    assert_eq!(
        e.property::<gst::Structure>("stats")
            .get::<f64>("denoise-seconds")
            .unwrap(),
        denoised,
        "late frames skip the denoising, to catch up"
    );
    let qos_messages = std::iter::from_fn(|| bus.pop_filtered(&[gst::MessageType::Qos])).count();
    assert_eq!(
        qos_messages, 3,
        "each is reported as GStreamer elements report QoS"
    );

    let (e2, mut h2, c2) = harness_with(|e| {
        e.set_property("reuse-interval", 1u32);
        e.set_property("qos", false);
    });
    push(&mut h2, &c2, face_rgb(), 0);
    h2.push_upstream_event(gst::event::Qos::new(
        gst::QOSType::Underflow,
        0.5,
        1_000_000_000,
        Some(frame_time(1)),
    ));
    push(&mut h2, &c2, &dim, 1);
    assert_eq!(stat(&e2, "qos-reused"), 0);
    assert_eq!(stat(&e2, "relit"), 2);
}

#[test]
fn only_the_head_the_shoulders_and_their_fade_are_touched() {
    let (w, ht) = (640u32, 480u32);
    let img = render_person(&State::default(), Vec3::new(1.0, 1.0, 1.0), w, ht);
    for format in [gst_video::VideoFormat::I420, gst_video::VideoFormat::Bgrx] {
        let e = element();
        e.set_property("face-tracking", false);
        e.set_property("crop-size", 0.5f64);
        e.set_property("feather", 0.25f64);
        e.set_property("target-location", target("left-key"));
        let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
        let c = caps(format, w, ht, 30);
        h.set_src_caps(c.clone());
        let input = buffer(&img, &c, gst::ClockTime::ZERO, FRAME);
        h.push(input.clone()).unwrap();
        let out = h.pull().unwrap();
        // The crop is the centred 240 x 240 square, the face 240 / 2.9 = 82.8
        // pixels high in it. The change is whole within a circle of a quarter
        // of the crop's side (60 pixels) about its centre, the head, joined
        // below the face to a band 1.3 face heights (108 pixels) either side
        // of the face's middle that runs down out of the frame, the shoulders;
        // it fades out over a quarter of the crop's side (60 pixels) beyond.
        // Above the crop's centre past 60 + 60 pixels from it, and beside the
        // band past 108 + 60 pixels, each with the field's grid cell (15
        // pixels) of interpolation, everything is byte for byte the input.
        let (a, b) = (input.map_readable().unwrap(), out.map_readable().unwrap());
        let info = gst_video::VideoInfo::from_caps(&c).unwrap();
        let (cx, cy, reach) = (320.0f32, 240.0f32, 60.0 + 60.0 + 15.0);
        let beside_the_band = 1.3 * 240.0 / 2.9 + 60.0 + 15.0;
        let stride = info.stride()[0] as usize;
        let bpp = if format == gst_video::VideoFormat::I420 {
            1
        } else {
            4
        };
        let mut inside_changed = 0;
        for y in 0..ht as usize {
            for x in 0..w as usize {
                let i = y * stride + x * bpp;
                let distance = (x as f32 + 0.5 - cx).hypot(y as f32 + 0.5 - cy);
                if distance <= 60.0 {
                    inside_changed += (a[i] != b[i]) as usize;
                } else if distance > reach && (y as f32) < cy
                    || (x as f32 + 0.5 - cx).abs() > beside_the_band
                {
                    assert_eq!(
                        a[i], b[i],
                        "{format:?}: pixel ({x}, {y}) beyond the fade changed"
                    );
                }
            }
        }
        assert!(
            inside_changed > 1000,
            "{format:?}: the face region is relit"
        );
        // 200 pixels below the crop's centre, under the face, the shoulders
        // are relit too.
        let row = (cy as usize + 200) * stride;
        let shoulders = (cx as usize - 40..cx as usize + 40)
            .filter(|&x| a[row + x * bpp] != b[row + x * bpp])
            .count();
        assert!(
            shoulders > 40,
            "{format:?}: {shoulders} of 80 shoulder pixels relit"
        );
    }
}
