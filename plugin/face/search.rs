//! Where to look for faces too small for the whole frame's letterbox.
//!
//! BlazeFace short-range sees the frame shrunk to 128 pixels across its longer
//! side, where a face a tenth of a 1080p frame's height is 7 pixels tall: too
//! small to find. So the detector looks again in smaller squares of the frame,
//! each shrunk to the same 128 pixels:
//!
//! - round a small face it found before, a square of [`NEAR_SIDE`] face heights
//!   (where that face is a quarter of the input, as BlazeFace's training faces
//!   are), so that it keeps finding the face it follows;
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
/// Height, in input pixels, under which a face counts as small: it is found
/// again round where it was as well as in the whole frame.
pub const MIN_FACE_INPUT: f32 = 24.0;
/// Side of the square looked in round a small face, in face heights.
pub const NEAR_SIDE: f32 = 4.0;
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
    face.height * INPUT / letterbox(width, height).side < MIN_FACE_INPUT
}

/// The square looked in round a small face.
pub fn around(face: &FaceBox, width: usize, height: usize) -> Square {
    Square {
        cx: face.cx,
        cy: face.cy,
        side: (NEAR_SIDE * face.height).max(INPUT),
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
        assert!(!is_small(&face(960.0, 540.0, 400.0), w, h));
        let near = around(&small, w, h);
        assert_eq!((near.cx, near.cy, near.side), (1500.0, 300.0, 432.0));
        // Near the frame's edge the square moves inside it.
        let edge = around(&face(1900.0, 20.0, 108.0), w, h);
        assert_eq!((edge.cx, edge.cy), (1920.0 - 216.0, 216.0));
    }

    #[test]
    fn a_frame_smaller_than_the_input_has_one_tile_per_scale() {
        assert_eq!(tiles(100, 80).len(), TILE_FRACTIONS.len());
    }
}
