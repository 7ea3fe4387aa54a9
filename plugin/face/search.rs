//! Where to look for faces too small for the whole frame's letterbox.
//!
//! BlazeFace short-range sees the frame shrunk to 128 pixels across its longer
//! side, where a face a tenth of a 1080p frame's height is 7 pixels tall: too
//! small to find. So the detector looks again in smaller squares of the frame,
//! each shrunk to the same 128 pixels:
//!
//! - round a small face, a square of [`NEAR_SIDE`] face heights, where the face
//!   is a third of the input: round the one the whole frame shows, whose box
//!   there is often coarse (the detector keeps the better scored of the two
//!   boxes), or, when the whole frame shows none, round the one found before,
//!   so that it keeps finding the face it follows; a small face found alone
//!   is looked for only in the look that boxed it, and in both every
//!   [`WHOLE_FRAME_EVERY`] detections;
//! - when it found no face at all, the next few squares of a fixed scan of
//!   tiles ([`TILES_PER_SEARCH`] a detection): the frame's shorter side, its
//!   half and its quarter. Each scale is for the faces the one above shows
//!   under [`MIN_FACE_INPUT`] input pixels tall, so its tiles overlap by the
//!   largest of them; over a cycle every face down to about 5% of the frame's
//!   height is at least that tall, and whole, in some tile.
//!
//! Pure arithmetic on squares; the detector runs the network on them.

use super::{FaceBox, Square};

/// Side of the detector's input, pixels.
const INPUT: f32 = super::detector::INPUT_SIZE as f32;
/// Height, in input pixels, down to which the scan's tiles show every face.
pub const MIN_FACE_INPUT: f32 = 24.0;
/// Side of the square looked in round a small face, in face heights: there the
/// face is a third of the input, 43 pixels high (more where the square is
/// clamped to the frame's shorter side).
pub const NEAR_SIDE: f32 = 3.0;
/// Height, in the whole frame's input pixels, under which a face counts as
/// small: shorter than in the square round it, where it is looked at again.
/// In the whole frame such a face's box is coarse, and jumps as the face
/// moves: the astronaut portrait in 720p is boxed 19 input pixels high there, and
/// leaning in and out by 6% her box switched between about 186 and 137 px
/// high (scores 0.57 and 0.94); round her it keeps 142-145 px, scaled back
/// (`tests/face.rs::a_face_leaning_in_and_out_keeps_its_box`). At this
/// height the two looks show the face alike where the square is not clamped
/// to the frame. In a 16:9 frame it is, first (a face over 240 px high in
/// 720p): there a face growing past this height goes from a look where it is
/// larger to the whole frame's, which no test measures yet.
pub const SMALL_FACE_INPUT: f32 = INPUT / NEAR_SIDE;
/// Small faces looked at again by one detection, the largest first: a call
/// with two people in view has both boxed by the closer look (the second's
/// square from its whole-frame box; only the largest is remembered).
pub const NEAR_LOOKS: usize = 2;
/// A small face found alone is looked for only in the look that boxed it
/// (round itself, or the whole frame), and in both every this many detections
/// (at the tracker's interval of 5 frames, every half second at 30 fps): a
/// face that comes in waits that long to be seen, and the detector's time on
/// a lone small face falls from two network runs a detection to four in
/// three detections.
pub const WHOLE_FRAME_EVERY: u32 = 3;
/// Tiles looked in by one detection that found no face.
pub const TILES_PER_SEARCH: usize = 2;
/// Tile sides as fractions of the frame's shorter side, each half the one before.
const TILE_FRACTIONS: [f32; 3] = [1.0, 0.5, 0.25];
/// Overlap of neighbouring tiles, as a fraction of their side: the tallest
/// face a scale is for is [`MIN_FACE_INPUT`] input pixels in tiles twice as
/// large, and lies whole in one of the tiles.
const TILE_OVERLAP: f32 = 2.0 * MIN_FACE_INPUT / INPUT;

/// The letterbox of the whole frame: the frame centred in a square of its longer side.
pub fn letterbox(width: usize, height: usize) -> Square {
    Square {
        side: width.max(height) as f32,
        ..Square::centred(width, height)
    }
}

/// Whether `face` is small in the whole frame's letterbox.
pub fn is_small(face: &FaceBox, width: usize, height: usize) -> bool {
    face.height * INPUT / letterbox(width, height).side < SMALL_FACE_INPUT
}

/// The square looked in round a small face lies on a grid, so that a still
/// face, boxed a pixel or so differently from one look to the next, is
/// looked at in the same square and found with the same box (unless its box
/// sits on a step, where it may take either of two squares). Its side in
/// steps of an eighth of an octave (9%).
const NEAR_SIDE_STEPS_PER_OCTAVE: f32 = 8.0;
/// Its centre in steps of a sixteenth of its side.
const NEAR_CENTRE_STEPS_PER_SIDE: f32 = 16.0;

/// The square looked in round a small face, on the grid of
/// [`NEAR_SIDE_STEPS_PER_OCTAVE`] and [`NEAR_CENTRE_STEPS_PER_SIDE`].
pub fn around(face: &FaceBox, width: usize, height: usize) -> Square {
    let octaves = ((NEAR_SIDE * face.height).max(INPUT) / INPUT).log2();
    let side = INPUT
        * ((octaves * NEAR_SIDE_STEPS_PER_OCTAVE).round() / NEAR_SIDE_STEPS_PER_OCTAVE).exp2();
    let step = side / NEAR_CENTRE_STEPS_PER_SIDE;
    let snap = |c: f32| (c / step).round() * step;
    Square {
        cx: snap(face.cx),
        cy: snap(face.cy),
        side,
    }
    .clamped(width, height)
}

/// The scan's tiles of a `width` × `height` frame, larger first, each row left to right.
pub fn tiles(width: usize, height: usize) -> Vec<Square> {
    let shorter = width.min(height) as f32;
    let mut out = Vec::new();
    for fraction in TILE_FRACTIONS {
        let side = (fraction * shorter).max(INPUT);
        let step = side * (1.0 - TILE_OVERLAP);
        let starts = |extent: usize| -> Vec<f32> {
            let last = (extent as f32 - side).max(0.0);
            let count = (last / step).ceil() as usize + 1;
            (0..count)
                .map(|k| (k as f32 * step).min(last) + side / 2.0)
                .collect()
        };
        for cy in starts(height) {
            for cx in starts(width) {
                out.push(Square { cx, cy, side });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn face(cx: f32, cy: f32, height: f32) -> FaceBox {
        FaceBox {
            cx,
            cy,
            width: height,
            height,
            score: 0.9,
            keypoints: [[cx, cy]; 6],
        }
    }

    fn contains(tile: &Square, f: &FaceBox) -> bool {
        let half = tile.side / 2.0;
        let inside = |c: f32, t: f32, extent: f32| {
            c - extent / 2.0 >= t - half && c + extent / 2.0 <= t + half
        };
        inside(f.cx, tile.cx, f.width) && inside(f.cy, tile.cy, f.height)
    }

    #[test]
    fn every_face_down_to_a_twentieth_of_the_height_is_large_in_the_letterbox_or_a_tile() {
        let (w, h) = (1920, 1080);
        let tiles = tiles(w, h);
        assert!(
            tiles.len() <= 90,
            "{} tiles: a scan would take too long",
            tiles.len()
        );
        for t in &tiles {
            assert!(t.cx - t.side / 2.0 >= -0.01 && t.cx + t.side / 2.0 <= w as f32 + 0.01);
            assert!(t.cy - t.side / 2.0 >= -0.01 && t.cy + t.side / 2.0 <= h as f32 + 0.01);
        }
        let whole = letterbox(w, h);
        for height in [54.0, 80.0, 108.0, 150.0, 250.0, 340.0] {
            // Every place the face lies whole in the frame.
            let half = (height / 2.0) as usize;
            for cx in (half..w - half).step_by(37) {
                for cy in (half..h - half).step_by(41) {
                    let f = face(cx as f32, cy as f32, height);
                    let best = tiles
                        .iter()
                        .chain([&whole])
                        .filter(|t| contains(t, &f))
                        .map(|t| height * INPUT / t.side)
                        .fold(0.0, f32::max);
                    assert!(
                        best >= MIN_FACE_INPUT,
                        "a {height} px face at ({cx}, {cy}) is at most {best:.1} input px tall"
                    );
                }
            }
        }
    }

    #[test]
    fn a_small_face_is_looked_for_round_where_it_was() {
        let (w, h) = (1920, 1080);
        let small = face(1500.0, 300.0, 108.0);
        assert!(is_small(&small, w, h));
        assert!(is_small(&face(960.0, 540.0, 600.0), w, h));
        assert!(!is_small(&face(960.0, 540.0, 700.0), w, h));
        let near = around(&small, w, h);
        // Three face heights, to an eighth of an octave, about the face.
        assert!((near.side / 324.0 - 1.0).abs() < 0.05, "{near:?}");
        assert!(contains(&near, &small), "{near:?}");
        // A pixel's difference in the box is the same square.
        for moved in [face(1501.0, 299.0, 108.0), face(1500.0, 300.0, 109.0)] {
            assert_eq!(around(&moved, w, h), near);
        }
        // Near the frame's edge the square moves inside it.
        let edge = around(&face(1900.0, 20.0, 108.0), w, h);
        assert_eq!(
            (edge.cx, edge.cy),
            (1920.0 - edge.side / 2.0, edge.side / 2.0)
        );
    }

    #[test]
    fn a_frame_smaller_than_the_input_has_one_tile_per_scale() {
        assert_eq!(tiles(100, 80).len(), TILE_FRACTIONS.len());
    }
}
