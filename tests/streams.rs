//! Streams that misbehave: resolution changes, timestamps that are missing,
//! repeated or jump about, very low and very high rates, and a model that
//! produces NaN. Every frame comes out, and nothing broken is ever shown.

use std::process::Command;

use deskstage::math::Vec3;
use deskstage::subject::State;
use gst::prelude::*;
use gst_check::Harness;
use lsydrelight_testkit::{
    checkout, default_model,
    element::{element, stat},
    person::{FACE_H, FACE_W, face_rgb, render_person},
    target,
    video::{FRAME, buffer, caps, frame_time, mean_abs_diff, to_rgb},
};

/// The element, configured, then started by the harness.
fn harness_with(configure: impl FnOnce(&gst::Element)) -> (gst::Element, Harness) {
    let e = element();
    e.set_property("reuse-interval", 1u32);
    // Streams that misbehave, whatever the face does: a fixed region.
    e.set_property("face-tracking", false);
    configure(&e);
    let h = Harness::with_element(&e, Some("sink"), Some("src"));
    (e, h)
}

fn harness() -> (gst::Element, Harness) {
    harness_with(|_| {})
}

#[test]
fn resolution_change_mid_stream() {
    let (e, mut h) = harness();
    for (w, ht) in [(320u32, 240u32), (640, 480), (200, 360)] {
        let c = caps(gst_video::VideoFormat::I420, w, ht, 30);
        h.set_src_caps(c.clone());
        let face = render_person(&State::default(), Vec3::new(1.0, 1.0, 1.0), w, ht);
        for i in 0..2 {
            h.push(buffer(&face, &c, frame_time(i), FRAME)).unwrap();
            let out = h.pull().unwrap();
            let oc = h.sinkpad().unwrap().current_caps().unwrap();
            assert_eq!(oc, c, "output follows the new size");
            assert_eq!(
                out.size(),
                gst_video::VideoInfo::from_caps(&c).unwrap().size()
            );
        }
    }
    assert!(
        stat(&e, "resets") >= 2,
        "each caps change resets the temporal state"
    );
}

#[test]
fn missing_repeated_and_jumping_timestamps() {
    let (e, mut h) = harness();
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    let pts: [Option<u64>; 9] = [
        Some(0),
        Some(1),
        None,
        Some(1),
        Some(1),
        Some(5),
        Some(2),
        None,
        Some(300),
    ];
    for (i, p) in pts.iter().enumerate() {
        let mut b = buffer(face_rgb(), &c, gst::ClockTime::ZERO, FRAME);
        b.get_mut().unwrap().set_pts(p.map(frame_time));
        h.push(b).unwrap();
        let out = h.pull().unwrap();
        assert_eq!(
            out.pts(),
            p.map(frame_time),
            "frame {i} keeps its timestamp"
        );
    }
    assert_eq!(stat(&e, "relit"), pts.len() as u64, "every frame is relit");
    assert!(
        stat(&e, "resets") >= 1,
        "a jump longer than reset-gap starts afresh"
    );
}

#[test]
fn one_and_a_hundred_and_twenty_frames_per_second() {
    for fps in [1i32, 120] {
        let (e, mut h) = harness();
        let c = caps(gst_video::VideoFormat::Nv12, FACE_W, FACE_H, fps);
        h.set_src_caps(c.clone());
        let d = gst::ClockTime::from_nseconds(1_000_000_000 / fps as u64);
        for i in 0..5u64 {
            h.push(buffer(face_rgb(), &c, d * i, d)).unwrap();
            assert_eq!(h.pull().unwrap().pts(), Some(d * i));
        }
        // At 1 fps frames are 1 s apart: no more than reset-gap, so no resets.
        assert_eq!(stat(&e, "resets"), 0, "{fps} fps");
        assert_eq!(stat(&e, "relit"), 5);
    }
}

/// A copy of the shipped model whose output is NaN for the left-key target.
fn nan_model() -> std::path::PathBuf {
    let out = checkout().join("target/test-models/nan");
    let status = Command::new(checkout().join(".venv/bin/python"))
        .current_dir(checkout().join("train"))
        .args(["-m", "lsyd.fixtures", "nan-model", "--model"])
        .arg(default_model())
        .arg("--out")
        .arg(&out)
        .arg("--trigger")
        .arg(target("left-key"))
        .arg("--normal")
        .arg(target("studio"))
        .status()
        .expect("the Python environment (scripts/setup.sh full) builds the NaN fixture");
    assert!(status.success());
    out
}

#[test]
fn nan_from_the_model_is_never_shown() {
    let model = nan_model();
    // The model is read when the element starts, which the harness does at once.
    // The target changes at once (no crossfade), so the trigger target is the one encoded.
    let (e, mut h) = harness_with(|e| {
        e.set_property("model-location", model.to_str().unwrap());
        e.set_property("target-transition", 0u64);
    });
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    let face = buffer(face_rgb(), &c, frame_time(0), FRAME);
    let push = |h: &mut Harness, i: u64| {
        let mut b = face.copy();
        b.get_mut().unwrap().set_pts(frame_time(i));
        h.push(b).unwrap();
        h.pull().unwrap()
    };
    e.set_property("target-location", target("studio"));
    let good = push(&mut h, 0);
    // Over the whole frame: 0.82 levels when written, the change being smooth
    // and faded out round the face; a frame passed through moves by 0.
    let relit = mean_abs_diff(&to_rgb(&good, &c), face_rgb());
    assert!(relit > 0.5, "relit normally: {relit}");

    e.set_property("target-location", target("left-key"));
    for i in 1..4 {
        let out = push(&mut h, i);
        let d = mean_abs_diff(&to_rgb(&out, &c), &to_rgb(&face, &c));
        assert_eq!(
            d,
            0.0,
            "a NaN result is replaced by the frame itself ({:?})",
            e.property::<gst::Structure>("stats")
        );
    }
    assert_eq!(stat(&e, "passed-through"), 3);
    assert_eq!(stat(&e, "non-finite"), 3);

    e.set_property("target-location", target("studio"));
    let back = push(&mut h, 4);
    assert!(
        mean_abs_diff(&to_rgb(&back, &c), &to_rgb(&good, &c)) < 0.05,
        "relighting recovers at once"
    );
}

#[test]
fn gaps_pass_through_as_gaps() {
    let (e, mut h) = harness();
    let c = caps(gst_video::VideoFormat::I420, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    h.push(buffer(face_rgb(), &c, frame_time(0), FRAME))
        .unwrap();
    h.pull().unwrap();
    assert!(
        h.push_event(
            gst::event::Gap::builder(frame_time(1))
                .duration(FRAME)
                .build()
        )
    );
    h.push(buffer(face_rgb(), &c, frame_time(2), FRAME))
        .unwrap();
    // The next frame comes out (the aggregator's thread has then passed the gap) ...
    assert_eq!(h.pull().unwrap().pts(), Some(frame_time(2)));
    // ... and downstream saw the gap as a gap.
    let gap = std::iter::from_fn(|| h.try_pull_event()).find(|e| e.type_() == gst::EventType::Gap);
    assert!(gap.is_some(), "the gap reaches downstream");
    assert_eq!(stat(&e, "relit"), 2);
}

#[test]
fn black_frames_stay_black() {
    // Camera start-up, fades and cuts to black: a frame that carries no light must
    // not come out with the network's idea of the face drawn into it.
    for format in [gst_video::VideoFormat::I420, gst_video::VideoFormat::Rgb] {
        let (e, mut h) = harness();
        let c = caps(format, FACE_W, FACE_H, 30);
        h.set_src_caps(c.clone());
        let info = gst_video::VideoInfo::from_caps(&c).unwrap();
        // Relight a face first, so the element has state a black frame must not reuse.
        h.push(buffer(face_rgb(), &c, frame_time(0), FRAME))
            .unwrap();
        h.pull().unwrap();
        let black = deskstage::monitor::RgbImage {
            width: FACE_W as usize,
            height: FACE_H as usize,
            data: vec![0; (FACE_W * FACE_H * 3) as usize],
        };
        for i in 1..4 {
            let input = buffer(&black, &c, frame_time(i), FRAME);
            let expected = input.map_readable().unwrap().to_vec();
            h.push(input).unwrap();
            let out = h.pull().unwrap();
            let out = out.map_readable().unwrap();
            let changed = out
                .iter()
                .zip(&expected[..info.size()])
                .filter(|(a, b)| a != b)
                .count();
            assert_eq!(changed, 0, "{format:?}: black frame {i} changed");
        }
        assert_eq!(stat(&e, "skipped-dark"), 3, "{format:?}");
    }
}
