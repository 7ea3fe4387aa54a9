//! Each face frame uses the monitor frame shown at its running time minus
//! `monitor-offset`: at different rates, with offsets, with a monitor stream that
//! starts late, stalls or ends, non-live and live.

use std::thread;
use std::time::Duration;

use deskstage::math::Vec3;
use gst::prelude::*;
use gst_check::Harness;
use lsydrelight_testkit::{
    element::{element, monitor_time, stat},
    init,
    person::{FACE_H, FACE_W, face_rgb, monitor_rgb},
    video::{buffer, caps, monitor_buffer, rgb_caps},
};

/// Expected monitor frame for a face time: the last monitor time at or before face − offset.
fn expected(monitor_times: &[u64], face: u64, offset: i64) -> Option<u64> {
    let t = face as i64 - offset;
    monitor_times
        .iter()
        .copied()
        .filter(|&m| m as i64 <= t)
        .max()
}

/// What a non-live run saw.
struct Run {
    faces: Vec<u64>,
    monitor: Vec<u64>,
    /// Per face frame, the running time of the monitor frame the element used.
    used: Vec<Option<u64>>,
    /// Per face frame, the relit frame's bytes.
    relit: Vec<Vec<u8>>,
    element: gst::Element,
}

impl Run {
    fn check(&self, offset: i64, what: &str) {
        assert_eq!(
            self.faces.len(),
            self.used.len(),
            "{what}: no face frame may be lost"
        );
        for (f, u) in self.faces.iter().zip(&self.used) {
            assert_eq!(
                *u,
                expected(&self.monitor, *f, offset),
                "{what}: face frame at {f} ns"
            );
        }
    }
}

/// Pushes face frames at `face_fps` and monitor frames at `monitor_fps` (only those in
/// [`monitor_from`, `monitor_until`)) from two threads: each aggregator pad blocks while
/// its last buffer is unused.
fn run_non_live(
    face_fps: u64,
    monitor_fps: u64,
    seconds: u64,
    offset: i64,
    monitor_from: u64,
    monitor_until: u64,
) -> Run {
    let e = element();
    e.set_property("monitor-offset", offset);
    e.set_property("monitor-timeout", 500_000_000u64);
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let mut mh = Harness::with_element(&e, Some("monitor_sink"), None);
    let c = caps(
        gst_video::VideoFormat::I420,
        FACE_W,
        FACE_H,
        face_fps as i32,
    );
    h.set_src_caps(c.clone());
    mh.set_src_caps(rgb_caps(256, 144, monitor_fps as i32));
    let monitor: Vec<u64> = (0..seconds * monitor_fps)
        .map(|i| i * 1_000_000_000 / monitor_fps)
        .filter(|&t| t >= monitor_from && t < monitor_until)
        .collect();
    let to_push = monitor.clone();
    let pusher = thread::spawn(move || {
        let d = gst::ClockTime::from_nseconds(1_000_000_000 / monitor_fps);
        for &t in &to_push {
            // The screen's colour changes every 1/30 s, whatever its frame rate.
            let colour = if (t * 30 / 1_000_000_000) % 2 == 0 {
                Vec3::new(0.9, 0.9, 0.9)
            } else {
                Vec3::new(0.2, 0.2, 0.5)
            };
            if mh
                .push(monitor_buffer(colour, gst::ClockTime::from_nseconds(t), d))
                .is_err()
            {
                break;
            }
        }
        mh.push_event(gst::event::Eos::new());
        mh
    });
    let faces: Vec<u64> = (0..seconds * face_fps)
        .map(|i| i * 1_000_000_000 / face_fps)
        .collect();
    let d = gst::ClockTime::from_nseconds(1_000_000_000 / face_fps);
    let mut out = Vec::new();
    for &t in &faces {
        h.push(buffer(face_rgb(), &c, gst::ClockTime::from_nseconds(t), d))
            .unwrap();
        while let Some(b) = h.try_pull() {
            out.push(b);
        }
    }
    h.push_event(gst::event::Eos::new());
    while out.len() < faces.len() {
        out.push(h.pull().expect("every face frame comes out"));
    }
    let used = out
        .iter()
        .map(|b| monitor_time(b).map(|t| t.nseconds()))
        .collect();
    let relit = out
        .iter()
        .map(|b| b.map_readable().unwrap().to_vec())
        .collect();
    pusher.join().unwrap();
    Run {
        faces,
        monitor,
        used,
        relit,
        element: e,
    }
}

#[test]
fn same_rate_picks_the_frame_shown_at_the_same_time() {
    let run = run_non_live(30, 30, 2, 0, 0, u64::MAX);
    run.check(0, "30/30 fps");
    assert_eq!(stat(&run.element, "known-source"), run.faces.len() as u64);
    // Every light was computed on the monitor stream's thread as its frame came,
    // so no face frame waited for one.
    assert_eq!(
        stat(&run.element, "monitor-arrival-decoded"),
        stat(&run.element, "monitor-frames")
    );
    assert_eq!(stat(&run.element, "monitor-decoded"), 0);
}

#[test]
fn faster_and_slower_monitor_streams() {
    let fast = run_non_live(30, 60, 2, 0, 0, u64::MAX);
    fast.check(0, "30 fps face, 60 fps monitor");
    // Every monitor frame is read. After the first few face frames, which find the
    // monitor stream twice as fast, only those a face frame uses are decoded.
    let last_face = *fast.faces.last().unwrap();
    let shown = fast.monitor.iter().filter(|&&m| m <= last_face).count() as u64;
    assert_eq!(stat(&fast.element, "monitor-frames"), shown);
    // (About 9 lights on arrival here: the mean of frames a face frame consumes
    // passes 1.25 at the fourth face frame; computing every one would be 120.)
    let on_arrival = stat(&fast.element, "monitor-arrival-decoded");
    assert!(on_arrival <= 16, "{on_arrival} lights computed on arrival");
    assert!(
        stat(&fast.element, "monitor-decoded") + on_arrival <= fast.faces.len() as u64 + 16,
        "lights of frames no face frame used were computed"
    );
    let slow = run_non_live(30, 10, 2, 0, 0, u64::MAX);
    slow.check(0, "30 fps face, 10 fps monitor");
    assert_eq!(stat(&slow.element, "monitor-decoded"), 0);
}

#[test]
fn lights_computed_as_frames_arrive_relight_as_those_computed_when_used() {
    // The screen changes colour every 1/30 s. At 30 fps every light is computed as
    // its frame arrives; at 60 fps (each colour shown twice) the lights are computed
    // when a face frame uses them, after the first few frames.
    let eager = run_non_live(30, 30, 1, 0, 0, u64::MAX);
    let lazy = run_non_live(30, 60, 1, 0, 0, u64::MAX);
    assert_eq!(stat(&eager.element, "monitor-decoded"), 0);
    assert!(stat(&lazy.element, "monitor-decoded") >= lazy.faces.len() as u64 - 5);
    assert_ne!(
        eager.relit[10], eager.relit[11],
        "the screen's colour changes the relit face"
    );
    for (k, (a, b)) in eager.relit.iter().zip(&lazy.relit).enumerate() {
        assert!(a == b, "face frame {k} relit differently");
    }
}

#[test]
fn offset_shifts_to_earlier_monitor_content() {
    let offset = 66_666_667; // two frames of display and camera latency
    let run = run_non_live(30, 30, 2, offset, 0, u64::MAX);
    run.check(offset, "with offset");
    assert_eq!(
        run.used[0], None,
        "nothing was on screen 67 ms before the first frame"
    );
}

#[test]
fn late_monitor_start_falls_back_then_follows() {
    let run = run_non_live(30, 30, 2, 0, 500_000_000, u64::MAX);
    run.check(0, "monitor starting at 0.5 s");
    assert!(run.used[..15].iter().all(Option::is_none));
    assert!(run.used[15..].iter().all(Option::is_some));
    assert_eq!(
        stat(&run.element, "fallbacks"),
        1,
        "one warning for the late start"
    );
}

#[test]
fn ended_monitor_falls_back_without_losing_frames() {
    let run = run_non_live(30, 30, 2, 0, 0, 1_000_000_000);
    assert_eq!(
        run.used.len(),
        run.faces.len(),
        "every face frame comes out after the monitor ends"
    );
    // Within monitor-timeout (0.5 s here) of its last frame the last content still counts.
    for (f, u) in run.faces.iter().zip(&run.used) {
        match *f {
            f if f < 1_000_000_000 => assert!(u.is_some()),
            f if f > 1_000_000_000 + 500_000_000 => {
                assert!(u.is_none(), "at {f} the monitor has ended")
            }
            _ => {}
        }
    }
    assert!(stat(&run.element, "predicted-source") >= 14);
}

/// A live face source (135 frames at 30 fps) and a live monitor fed by hand at
/// 10 fps that goes silent from 1.5 s to 3 s. Every face frame comes out; those
/// after monitor-timeout into the silence use the predicted light, and those after
/// the monitor returns use it again.
#[test]
fn live_sources_stall_and_recover() {
    init();
    let pipeline = gst::parse::launch(
        "lsydrelight name=r monitor-timeout=200000000 latency=50000000 \
         videotestsrc is-live=true num-buffers=135 pattern=ball ! video/x-raw,format=I420,width=320,height=240,framerate=30/1 ! r.sink \
         appsrc name=mon is-live=true do-timestamp=true format=time \
            caps=video/x-raw,format=RGB,width=256,height=144,framerate=10/1 ! r.monitor_sink \
         r.src ! appsink name=out sync=false",
    )
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    let r = pipeline.by_name("r").unwrap();
    let mon = pipeline
        .by_name("mon")
        .unwrap()
        .downcast::<gst_app::AppSrc>()
        .unwrap();
    let out = pipeline
        .by_name("out")
        .unwrap()
        .downcast::<gst_app::AppSink>()
        .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let feeder = thread::spawn(move || {
        let frame = monitor_rgb(Vec3::new(0.8, 0.8, 0.8));
        let start = std::time::Instant::now();
        let mut next = Duration::ZERO;
        while next < Duration::from_millis(4600) {
            let now = start.elapsed();
            if now < next {
                thread::sleep(next - now);
            }
            let silent = (Duration::from_millis(1500)..Duration::from_millis(3000)).contains(&next);
            if !silent {
                let mut b = gst::Buffer::from_slice(frame.data.clone());
                b.get_mut()
                    .unwrap()
                    .set_duration(gst::ClockTime::from_mseconds(100));
                if mon.push_buffer(b).is_err() {
                    break;
                }
            }
            next += Duration::from_millis(100);
        }
        let _ = mon.end_of_stream();
    });
    let mut frames = Vec::new();
    while let Some(s) = out.try_pull_sample(gst::ClockTime::from_seconds(30)) {
        let b = s.buffer().unwrap();
        let seg = s
            .segment()
            .unwrap()
            .downcast_ref::<gst::ClockTime>()
            .unwrap()
            .clone();
        frames.push((
            seg.to_running_time(b.pts().unwrap()).unwrap(),
            monitor_time(b),
        ));
    }
    feeder.join().unwrap();
    // Read the bus before NULL flushes it.
    let bus = pipeline.bus().unwrap();
    let warnings: Vec<String> =
        std::iter::from_fn(|| bus.pop_filtered(&[gst::MessageType::Warning]))
            .filter_map(|m| match m.view() {
                gst::MessageView::Warning(w) => Some(w.error().to_string()),
                _ => None,
            })
            .collect();
    pipeline.set_state(gst::State::Null).unwrap();

    assert_eq!(frames.len(), 135, "every face frame comes out");
    let ms = |t: u64| gst::ClockTime::from_mseconds(t);
    // Running times start when the pipeline plays; the feeder started then too, so
    // allow a little slack around the silence's edges.
    let silent: Vec<_> = frames
        .iter()
        .filter(|(t, _)| *t > ms(1900) && *t < ms(2900))
        .collect();
    let back: Vec<_> = frames.iter().filter(|(t, _)| *t > ms(3600)).collect();
    let before: Vec<_> = frames
        .iter()
        .filter(|(t, _)| *t > ms(300) && *t < ms(1400))
        .collect();
    assert!(
        before.iter().all(|(_, m)| m.is_some()),
        "the live monitor lights the frames"
    );
    assert!(
        !silent.is_empty() && silent.iter().all(|(_, m)| m.is_none()),
        "a stalled monitor is not used"
    );
    assert!(
        !back.is_empty() && back.iter().all(|(_, m)| m.is_some()),
        "relighting follows the monitor again"
    );
    assert!(stat(&r, "fallbacks") >= 1);
    let stalls = warnings.iter().filter(|w| w.contains("stalled")).count();
    assert_eq!(stalls, 1, "one warning for the stall: {warnings:?}");
}

#[test]
fn live_rates_align_by_running_time() {
    init();
    let pipeline = gst::parse::launch(
        "lsydrelight name=r latency=40000000 \
         videotestsrc is-live=true ! video/x-raw,format=NV12,width=320,height=240,framerate=30/1 ! r.sink \
         videotestsrc is-live=true pattern=snow ! video/x-raw,format=BGRx,width=256,height=144,framerate=60/1 ! r.monitor_sink \
         r.src ! appsink name=out sync=false",
    )
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    let out = pipeline
        .by_name("out")
        .unwrap()
        .downcast::<gst_app::AppSink>()
        .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let mut checked = 0;
    for _ in 0..40 {
        let s = out.pull_sample().unwrap();
        let b = s.buffer().unwrap();
        let seg = s
            .segment()
            .unwrap()
            .downcast_ref::<gst::ClockTime>()
            .unwrap()
            .clone();
        let face_rt = seg.to_running_time(b.pts().unwrap()).unwrap();
        if let Some(m) = monitor_time(b) {
            // At 60 fps the monitor frame used is shown at most one monitor frame before the face frame.
            assert!(m <= face_rt, "monitor frame {m} after face frame {face_rt}");
            assert!(
                face_rt - m < gst::ClockTime::from_mseconds(17 + 5),
                "face {face_rt}, monitor {m}"
            );
            checked += 1;
        }
    }
    // Latency: live, and at least the element's configured latency.
    let mut q = gst::query::Latency::new();
    assert!(out.static_pad("sink").unwrap().peer_query(&mut q));
    let (live, min, _) = q.result();
    assert!(live);
    assert!(
        min >= gst::ClockTime::from_mseconds(40),
        "reported latency {min}"
    );
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(
        checked > 30,
        "most live frames align with the 60 fps monitor ({checked}/40)"
    );
}

/// The minimum latency a live pipeline reports through the element.
fn reported_latency(element_properties: &str) -> gst::ClockTime {
    let pipeline = gst::parse::launch(&format!(
        "lsydrelight name=r {element_properties} \
         videotestsrc is-live=true ! video/x-raw,width=160,height=120,framerate=30/1 ! r.sink \
         r.src ! appsink name=out sync=false"
    ))
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    let out = pipeline
        .by_name("out")
        .unwrap()
        .downcast::<gst_app::AppSink>()
        .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    out.pull_sample().expect("a relit frame");
    let mut q = gst::query::Latency::new();
    assert!(out.static_pad("sink").unwrap().peer_query(&mut q));
    pipeline.set_state(gst::State::Null).unwrap();
    let (live, min, _) = q.result();
    assert!(live);
    min
}

#[test]
fn the_reported_latency_allows_for_relighting() {
    // Relighting starts only once a frame's monitor light is in (or its wait timed
    // out), so its time must be in the latency a live sink allows for, or the sink
    // drops every frame that took longer than the sink's own margin.
    init();
    let none = reported_latency("processing-latency=0");
    assert_eq!(
        reported_latency("") - none,
        gst::ClockTime::from_mseconds(33),
        "default processing latency"
    );
    assert_eq!(
        reported_latency("processing-latency=50000000 monitor-offset=-20000000") - none,
        gst::ClockTime::from_mseconds(70),
        "processing latency and the wait for a lagging screen capture"
    );
}

#[test]
fn a_silent_monitor_branch_in_a_non_live_pipeline_is_named() {
    // A monitor branch that never produces holds a non-live pipeline (the element
    // waits for the monitor frame that lit each face frame): say so.
    init();
    let pipeline = gst::parse::launch(
        "videotestsrc num-buffers=30 ! video/x-raw,width=160,height=120 \
         ! lsydrelight name=r monitor-timeout=300000000 ! fakesink \
         appsrc name=screen is-live=false format=time \
         caps=video/x-raw,format=RGB,width=64,height=32,framerate=10/1 ! r.monitor_sink",
    )
    .unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let started = std::time::Instant::now();
    let msg = pipeline
        .bus()
        .unwrap()
        .timed_pop_filtered(
            gst::ClockTime::from_seconds(10),
            &[gst::MessageType::Warning, gst::MessageType::Error],
        )
        .expect("a warning, not a silent hang");
    let waited = started.elapsed();
    pipeline.set_state(gst::State::Null).unwrap();
    let gst::MessageView::Warning(w) = msg.view() else {
        panic!("expected a warning, got {msg:?}");
    };
    let text = format!("{} | {:?}", w.error(), w.debug());
    assert!(
        text.contains("waiting for the monitor stream") && text.contains("monitor_sink"),
        "{text}"
    );
    assert!(
        waited >= std::time::Duration::from_millis(300),
        "warned before monitor-timeout: {waited:?}"
    );
}
