//! The guidance's tests: simulated sessions of screen and camera frames, and
//! what the user is told about them.

use super::*;

/// A frontal face `size` pixels high, turned by `turn` (nose offset in face
/// widths), with luminance `luminance`.
fn face(size: f32, turn: f32, luminance: f64) -> Face {
    Face {
        width: size,
        height: size,
        eyes: [[100.0 - 0.2 * size, 100.0], [100.0 + 0.2 * size, 100.0]],
        nose: [100.0 + turn * size, 100.0 + 0.15 * size],
        mouth: [100.0, 100.0 + 0.3 * size],
        luminance,
    }
}

/// A screen light of one grey level everywhere; its luminance is `level`.
fn grey(level: f64) -> Vec<f32> {
    vec![level as f32; 3 * LIGHT_ROWS * LIGHT_COLS]
}

/// A screen that alternates between dark and bright every 0.5 s, its frames
/// at 30 fps, and a camera at 10 fps whose face is lit by `room` plus the screen.
fn run(seconds: f64, room: f64, face_at: impl Fn(f64) -> Option<(f32, f32)>) -> Guidance {
    run_faces(seconds, room, |t, luminance| {
        face_at(t).map(|(size, turn)| face(size, turn, luminance))
    })
}

/// As [`run`], with the whole face given for each time and face luminance.
fn run_faces(seconds: f64, room: f64, face_at: impl Fn(f64, f64) -> Option<Face>) -> Guidance {
    let mut g = Guidance::new();
    let screen = |t: f64| if (t * 2.0) as i64 % 2 == 0 { 0.1 } else { 0.6 };
    for i in 0..(seconds * 30.0) as usize {
        let t = i as f64 / 30.0;
        g.screen(t, &grey(screen(t)));
        if i % 3 == 0 {
            g.camera(t, face_at(t, 0.5 * (room + screen(t))));
        }
    }
    g.finish();
    g
}

fn kinds(g: &Guidance) -> Vec<WarningKind> {
    g.summary().warnings.iter().map(|w| w.kind).collect()
}

/// Head turning back and forth, a full cycle every 4 s.
fn moving(t: f64) -> Option<(f32, f32)> {
    Some((80.0, 0.15 * (t * std::f64::consts::TAU / 4.0).sin() as f32))
}

#[test]
fn a_good_capture_counts_usable_frames_and_warns_of_nothing() {
    let g = run(12.0, 0.05, moving);
    let s = g.summary();
    assert_eq!(s.camera_frames, 120);
    assert_eq!(s.usable_frames, 120);
    assert!(kinds(&g).is_empty(), "{:?}", s.warnings);
    // The face is 0.05 room + screen: the screen's share is mean screen / (0.05 + mean screen).
    let want = 0.35 / 0.4;
    let share = s.monitor_share.unwrap();
    assert!((share - want).abs() < 0.02, "{share} vs {want}");
    assert!(s.pose_bins_covered >= 3, "{:?}", s.pose_bin_frames);
}

#[test]
fn a_bright_room_is_reported_with_the_measured_share() {
    let g = run(12.0, 2.0, moving);
    assert_eq!(kinds(&g), [WarningKind::RoomOverpowersMonitor]);
    let share = g.summary().monitor_share.unwrap();
    assert!((share - 0.35 / 2.35).abs() < 0.02, "{share}");
    assert!(g.summary().warnings[0].message.contains("15 %"));
}

#[test]
fn a_face_that_leaves_is_reported_once_per_absence() {
    let g = run(12.0, 0.05, |t| {
        if (4.0..7.0).contains(&t) {
            None
        } else {
            moving(t)
        }
    });
    assert_eq!(kinds(&g), [WarningKind::FaceLost]);
    let w = &g.summary().warnings[0];
    assert!(w.at > 4.85 && w.at < 5.3, "{w:?}");
    let lost = g.summary().face_lost_seconds;
    assert!((lost - 3.1).abs() < 0.01, "{lost}");
    assert_eq!(g.summary().usable_frames, 90);
}

#[test]
fn a_face_gone_for_good_is_not_a_frozen_pose() {
    let g = run(12.0, 0.05, |t| if t < 3.0 { moving(t) } else { None });
    assert_eq!(kinds(&g), [WarningKind::FaceLost]);
}

#[test]
fn a_frozen_pose_is_reported_and_small_faces_are_not_usable() {
    let g = run(12.0, 0.05, |_| Some((30.0, 0.0)));
    assert_eq!(kinds(&g), [WarningKind::PoseFrozen]);
    assert_eq!(g.summary().usable_frames, 0);
    assert_eq!(g.summary().frames_with_face, 120);
}

/// Holding each of a few poses for 2 s, then moving to the next.
fn holding(t: f64) -> Option<(f32, f32)> {
    Some((80.0, [-0.15, 0.0, 0.15][(t / 2.0) as usize % 3]))
}

#[test]
fn a_head_that_never_holds_a_pose_gives_no_pairs_and_is_told_how_to() {
    // Sliding sideways at 20 px a second (0.06 eye distances a camera frame), and
    // turning to and fro: never the same place twice, not even across a screen change.
    let g = run_faces(25.0, 0.05, |t, luminance| {
        let mut f = face(80.0, 0.0, luminance);
        let shift = 20.0 * t as f32;
        let [right, left] = &mut f.eyes;
        for p in [right, left, &mut f.nose, &mut f.mouth] {
            p[0] += shift;
        }
        f.nose[0] += 12.0 * (t * std::f64::consts::TAU / 4.0).sin() as f32;
        Some(f)
    });
    let s = g.summary();
    assert_eq!(s.usable_frames, 250);
    assert_eq!(s.pairable_frames, 0);
    assert_eq!(kinds(&g), [WarningKind::FewPairs]);
    let w = &s.warnings[0];
    assert!(
        w.at >= PAIRING_WINDOW_SECONDS && w.at < PAIRING_WINDOW_SECONDS + 0.2,
        "{w:?}"
    );
    assert!(w.message.contains("only 0 of the last 2"), "{}", w.message);
    assert!(w.message.contains("hold your head still"), "{}", w.message);
}

#[test]
fn holding_poses_while_the_screen_changes_gives_pairs() {
    let g = run(25.0, 0.05, holding);
    let s = g.summary();
    // Every frame shares its pose with frames half a second away, under the other light.
    assert_eq!(s.pairable_frames, s.usable_frames);
    assert!(kinds(&g).is_empty(), "{:?}", s.warnings);
}

#[test]
fn the_same_pose_under_the_same_light_is_no_pair() {
    let mut g = Guidance::new();
    for i in 0..300 {
        let t = i as f64 / 10.0;
        g.screen(t, &grey(0.3));
        g.camera(t, Some(face(80.0, 0.0, 0.4)));
    }
    g.finish();
    assert_eq!(g.summary().pairable_frames, 0);
}

#[test]
fn a_steady_screen_leaves_the_share_unknown() {
    let mut g = Guidance::new();
    for i in 0..100 {
        let t = i as f64 / 10.0;
        g.screen(t, &grey(0.3));
        g.camera(t, Some(face(80.0, 0.0, 0.4)));
    }
    g.finish();
    assert_eq!(g.summary().monitor_share, None);
}

#[test]
fn camera_frames_wait_for_the_screen_frame_after_them() {
    let mut g = Guidance::new();
    g.camera(0.05, Some(face(80.0, 0.0, 0.4)));
    assert_eq!(g.summary().camera_frames, 0, "its light is not known yet");
    g.screen(0.0, &grey(0.2));
    assert_eq!(g.summary().camera_frames, 0);
    g.screen(0.1, &grey(0.2));
    assert_eq!(g.summary().usable_frames, 1);
}

#[test]
fn face_luminance_reads_the_inner_face_in_linear_light() {
    // A 20x20 frame, mid-grey (sRGB 128 is linear 0.2158) inside, white outside.
    let (w, h) = (20usize, 20usize);
    let mut rgb = vec![255u8; w * h * 3];
    for y in 5..15 {
        for x in 5..15 {
            rgb[(y * w + x) * 3..(y * w + x) * 3 + 3].fill(128);
        }
    }
    let l = face_luminance(&rgb, w * 3, w, h, [10.0, 10.0], [16.0, 16.0]);
    assert!((l - 0.2158).abs() < 1e-3, "{l}");
    assert!((light_luminance(&[1.0; 6]) - 1.0).abs() < 1e-9);
}
