//! Following the face, without GStreamer: where the face is in a frame, and
//! which square of the frame the relighting network sees.
//!
//! - [`detector`]: BlazeFace short-range (`models/face/blazeface.onnx`) through
//!   ONNX Runtime: a frame to the faces in it ([`FaceBox`]).
//! - [`search`]: the squares the detector looks in for faces too small for the
//!   whole frame: round a small face it found, and a scan of tiles.
//! - [`tracker`]: pure logic over the detector's answers: when to run it,
//!   which face to follow, smoothing, and a fade when the face goes or comes.
//! - Here: the face box, the square crop and the one rule between them
//!   ([`crop_from_face`]), where the face lies in a crop moved to fit the
//!   frame ([`face_place`]), and the small resampler both use ([`sample_square`]).

pub mod detector;
pub mod search;
pub mod tracker;

pub use detector::{DetectorError, FaceDetector};
pub use tracker::{FaceTracker, Tracked, TrackerSettings};

use crate::frame::{Crop, FacePlace, Frame};

/// A face found in a frame, in the frame's pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceBox {
    pub cx: f32,
    pub cy: f32,
    pub width: f32,
    pub height: f32,
    /// The detector's confidence, in [0, 1].
    pub score: f32,
    /// (x, y) of [`KEYPOINTS`], in order.
    pub keypoints: [[f32; 2]; 6],
}

/// BlazeFace's keypoints. Right and left are the person's own: the right eye is
/// on the image's left in an unmirrored camera.
pub const KEYPOINTS: [&str; 6] = [
    "right eye",
    "left eye",
    "nose tip",
    "mouth centre",
    "right ear",
    "left ear",
];

impl FaceBox {
    pub fn area(&self) -> f32 {
        self.width * self.height
    }

    /// Whether `other` is a detection of the same face: their centres are
    /// less than a face height apart.
    pub fn is_same_face(&self, other: &FaceBox) -> bool {
        let distance = (self.cx - other.cx).hypot(self.cy - other.cy);
        distance < self.height.max(other.height)
    }
}

/// A square region of a frame, in the frame's pixels: centre and side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Square {
    pub cx: f32,
    pub cy: f32,
    pub side: f32,
}

impl Square {
    /// The frame's centred full-height (or full-width) square: the element's
    /// crop before it followed the face.
    pub fn centred(width: usize, height: usize) -> Square {
        Square {
            cx: width as f32 / 2.0,
            cy: height as f32 / 2.0,
            side: width.min(height) as f32,
        }
    }

    /// No larger than the frame's shorter side, and moved (not shrunk) to lie
    /// inside the frame: near an edge the face is off-centre in the crop
    /// rather than the crop holding what is not in the frame.
    pub fn clamped(self, width: usize, height: usize) -> Square {
        let side = self.side.min(width.min(height) as f32).max(1.0);
        let place = |c: f32, extent: usize| c.clamp(side / 2.0, extent as f32 - side / 2.0);
        Square {
            cx: place(self.cx, width),
            cy: place(self.cy, height),
            side,
        }
    }

    /// As the frame module's crop: whole, even pixels inside the frame, for
    /// [`crate::frame::sample_crop`] and the lighting change.
    pub fn crop(&self, width: usize, height: usize) -> Crop {
        Crop::centred(
            width,
            height,
            (self.cx / width as f32) as f64,
            (self.cy / height as f32) as f64,
            (self.side / width.min(height) as f32) as f64,
        )
    }
}

/// Where the face the rule's square `wanted` was made round lies in `crop`
/// (the square moved, or shrunk, to fit the frame), in fractions of the
/// crop's side.
pub fn face_place(wanted: Square, crop: Crop, rule: CropRule) -> FacePlace {
    let face_height = wanted.side / rule.side;
    let side = crop.size.max(1) as f32;
    FacePlace {
        centre: [
            (wanted.cx - crop.x as f32) / side,
            (wanted.cy + rule.lift * face_height - crop.y as f32) / side,
        ],
        height: face_height / side,
    }
}

/// Side of the crop, in face heights (the height of BlazeFace's box, which runs
/// from the hairline to the chin).
///
/// Measured so that on the simulator's default person, sitting as in the
/// training captures, the rule gives back the captures' framing. A capture is
/// the centred full-height square of the desk camera (the same 40° vertical
/// field of view, at 256 × 256), so on a 640 × 360 frame the crop must be 360 px
/// square and centred. `tests/face.rs::the_crop_rule_gives_the_training_framing`
/// detects the face in 640 × 360 frames of 32 poses of the training sessions'
/// motion and prints, per pose, frame height / face height (mean 2.93, sd 0.33)
/// and (face centre − frame centre) / face height (mean 0.203, sd 0.133; 2.92
/// and 0.224 before the detector looked closer at small faces, which these
/// are: [`search::SMALL_FACE_INPUT`]); it fails when these constants drift
/// from the means.
pub const CROP_SIDE: f32 = 2.9;
/// How far the crop's centre is above the face box's centre, in face heights:
/// the captures hold the face a little below the middle, the hair above it.
pub const CROP_LIFT: f32 = 0.22;

/// The rule from a face box to the network's square: `side` face heights square,
/// its centre `lift` face heights above the face's. A model states its own
/// (`crop` in `model.json`, the model contract); [`CropRule::TRAINING`] is the
/// one measured on the training captures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CropRule {
    pub side: f32,
    pub lift: f32,
}

impl CropRule {
    pub const TRAINING: CropRule = CropRule {
        side: CROP_SIDE,
        lift: CROP_LIFT,
    };
}

impl Default for CropRule {
    fn default() -> Self {
        CropRule::TRAINING
    }
}

/// The crop for a face by `rule`. Not clamped to the frame.
pub fn crop_from_face(face: &FaceBox, rule: CropRule) -> Square {
    Square {
        cx: face.cx,
        cy: face.cy - rule.lift * face.height,
        side: rule.side * face.height,
    }
}

/// `square` of `frame` resampled to `res`×`res` RGB in [0, 1], row by row; what
/// lies outside the frame is black.
///
/// Each output pixel averages up to 4 × 4 samples spread over its footprint:
/// enough against aliasing for a detector's 128 px and a 16 px thumbnail, and a
/// fixed cost whatever the frame's size (the element's exact area resampling
/// reads every pixel of the region, which for a whole 1080p frame costs more
/// than the detector).
pub fn sample_square(frame: &Frame, square: Square, res: usize) -> Vec<[f32; 3]> {
    let scale = square.side / res as f32;
    let n = (scale.ceil() as usize).clamp(1, 4);
    // Frame pixel of each sample along an axis, None outside the frame.
    let positions = |start: f32, extent: usize| -> Vec<Option<usize>> {
        (0..res * n)
            .map(|k| {
                let p = start + (k as f32 + 0.5) * scale / n as f32;
                (p >= 0.0 && p < extent as f32).then_some(p as usize)
            })
            .collect()
    };
    let xs = positions(square.cx - square.side / 2.0, frame.width);
    let ys = positions(square.cy - square.side / 2.0, frame.height);
    let planes = &frame.planes;
    // Byte offsets are worked out once per sample column and row, not per sample.
    let (means, covered) = match frame.format.packed() {
        Some((offsets, bpp)) => {
            let data = planes[0].data;
            let cols = offsets_of(&xs, |x| x * bpp);
            let rows = offsets_of(&ys, |y| y * planes[0].stride);
            average(&cols, &rows, n, |&row, &col| {
                offsets.map(|o| data[row + col + o] as f32 / 255.0)
            })
        }
        None => {
            let [cb, cr] = frame.format.chroma_lanes();
            let chroma_col = |(_, sub, bpp, byte): (usize, usize, usize, usize), x: usize| {
                (x / sub) * bpp + byte
            };
            let chroma_row = |(plane, sub, _, _): (usize, usize, usize, usize), y: usize| {
                (y / sub) * planes[plane].stride
            };
            let cols = offsets_of(&xs, |x| [x, chroma_col(cb, x), chroma_col(cr, x)]);
            let rows = offsets_of(&ys, |y| {
                [y * planes[0].stride, chroma_row(cb, y), chroma_row(cr, y)]
            });
            let (luma, cb_data, cr_data) = (planes[0].data, planes[cb.0].data, planes[cr.0].data);
            let (yuv, covered) = average(&cols, &rows, n, |row, col| {
                [
                    luma[row[0] + col[0]] as f32,
                    cb_data[row[1] + col[1]] as f32,
                    cr_data[row[2] + col[2]] as f32,
                ]
            });
            // Averaged before converting: the conversion is affine.
            let rgb = yuv.iter().map(|v| frame.matrix.to_rgb(v[0], v[1], v[2]));
            (rgb.collect(), covered)
        }
    };
    // Samples outside the frame count as black.
    means
        .iter()
        .zip(covered)
        .map(|(rgb, share)| rgb.map(|v| v.clamp(0.0, 1.0) * share))
        .collect()
}

/// Per sample position (None outside the frame), what reading it needs.
fn offsets_of<T>(positions: &[Option<usize>], offset: impl Fn(usize) -> T) -> Vec<Option<T>> {
    positions.iter().map(|p| p.map(&offset)).collect()
}

/// Per output pixel: the mean of `read` over its n × n samples inside the frame,
/// and the share of its samples inside the frame. `cols` and `rows` hold what
/// reading a sample column and row needs, None outside the frame.
fn average<C, R>(
    cols: &[Option<C>],
    rows: &[Option<R>],
    n: usize,
    read: impl Fn(&R, &C) -> [f32; 3],
) -> (Vec<[f32; 3]>, Vec<f32>) {
    let pixels = (cols.len() / n) * (rows.len() / n);
    let (mut means, mut covered) = (Vec::with_capacity(pixels), Vec::with_capacity(pixels));
    for row in rows.chunks_exact(n) {
        for col in cols.chunks_exact(n) {
            let mut sum = [0f32; 3];
            let mut inside = 0;
            for y in row.iter().flatten() {
                for x in col.iter().flatten() {
                    let v = read(y, x);
                    sum = [sum[0] + v[0], sum[1] + v[1], sum[2] + v[2]];
                    inside += 1;
                }
            }
            means.push(sum.map(|s| s / inside.max(1) as f32));
            covered.push(inside as f32 / (n * n) as f32);
        }
    }
    (means, covered)
}

/// A square face box centred at (`cx`, `cy`), for the module's tests.
#[cfg(test)]
pub(crate) fn face(cx: f32, cy: f32, size: f32) -> FaceBox {
    FaceBox {
        cx,
        cy,
        width: size,
        height: size,
        score: 0.9,
        keypoints: [[cx, cy]; 6],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{Frame, OwnedFrame, PixelFormat, Plane, YuvMatrix};

    #[test]
    fn a_square_is_moved_into_the_frame_and_no_larger_than_it() {
        let s = Square {
            cx: 20.0,
            cy: 350.0,
            side: 200.0,
        }
        .clamped(640, 360);
        assert_eq!((s.cx, s.cy, s.side), (100.0, 260.0, 200.0));
        let s = Square {
            cx: 320.0,
            cy: 180.0,
            side: 500.0,
        }
        .clamped(640, 360);
        assert_eq!((s.cx, s.cy, s.side), (320.0, 180.0, 360.0));
        let c = Square::centred(640, 360).crop(640, 360);
        assert_eq!((c.x, c.y, c.size), (140, 0, 360));
    }

    #[test]
    fn a_face_near_the_top_sits_high_in_a_crop_moved_into_the_frame() {
        // The astronaut in 720p: her square reaches 119 px past the top, so the
        // crop is moved down and her face is 0.37 of the crop from its top,
        // where the rule alone would put it at 0.58.
        let astronaut = face(600.0, 207.0, 195.0);
        let wanted = crop_from_face(&astronaut, CropRule::TRAINING);
        let crop = wanted.clamped(1280, 720).crop(1280, 720);
        assert_eq!(crop.y, 0);
        let place = face_place(wanted, crop, CropRule::TRAINING);
        assert!(
            (place.centre[1] - 207.0 / crop.size as f32).abs() < 1e-3,
            "{place:?}"
        );
        assert!((place.centre[0] - (600.0 - crop.x as f32) / crop.size as f32).abs() < 1e-3);
        assert!((place.height - 195.0 / crop.size as f32).abs() < 1e-3);
        // A crop the rule did not move puts the face where the rule says.
        let free = crop_from_face(&face(600.0, 400.0, 195.0), CropRule::TRAINING);
        let place = face_place(free, free.crop(1280, 720), CropRule::TRAINING);
        let rule = FacePlace::default();
        assert!((place.centre[1] - rule.centre[1]).abs() < 0.01, "{place:?}");
        assert!((place.height - rule.height).abs() < 0.01, "{place:?}");
    }

    #[test]
    fn the_crop_is_above_the_face_and_larger() {
        let s = crop_from_face(&face(200.0, 100.0, 60.0), CropRule::TRAINING);
        assert_eq!(s.cx, 200.0);
        assert!((s.cy - (100.0 - CROP_LIFT * 60.0)).abs() < 1e-4);
        assert!((s.side - CROP_SIDE * 60.0).abs() < 1e-4);
    }

    #[test]
    fn sampling_reads_rgb_and_yuv_alike_and_pads_with_black() {
        // A 64x32 frame, left half red, right half blue, as RGB and as I420.
        let (w, h) = (64usize, 32usize);
        let rgb: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                if i % w < w / 2 {
                    [200, 0, 0]
                } else {
                    [0, 0, 200]
                }
            })
            .collect();
        let m = YuvMatrix::BT601_LIMITED;
        let yuv_of = |x: usize| {
            m.from_rgb(if x < w / 2 {
                [200.0 / 255.0, 0.0, 0.0]
            } else {
                [0.0, 0.0, 200.0 / 255.0]
            })
        };
        let luma: Vec<u8> = (0..w * h).map(|i| yuv_of(i % w)[0].round() as u8).collect();
        let chroma = |c: usize| -> Vec<u8> {
            (0..(w / 2) * (h / 2))
                .map(|i| yuv_of(2 * (i % (w / 2)))[c].round() as u8)
                .collect()
        };
        let (cb, cr) = (chroma(1), chroma(2));
        let i420 = Frame {
            format: PixelFormat::I420,
            width: w,
            height: h,
            planes: [
                Plane {
                    data: &luma,
                    stride: w,
                },
                Plane {
                    data: &cb,
                    stride: w / 2,
                },
                Plane {
                    data: &cr,
                    stride: w / 2,
                },
            ],
            matrix: m,
        };
        // The letterbox of the whole frame: a 64x64 square, black above and below.
        let square = Square::centred(w, h);
        let square = Square {
            side: w as f32,
            ..square
        };
        for frame in [Frame::packed_rgb(&rgb, w, h), i420] {
            let out = sample_square(&frame, square, 8);
            let px = |x: usize, y: usize| out[y * 8 + x];
            assert_eq!(px(3, 0), [0.0; 3], "above the frame");
            assert_eq!(px(3, 7), [0.0; 3], "below the frame");
            for (x, want) in [
                (1, [200.0 / 255.0, 0.0, 0.0]),
                (6, [0.0, 0.0, 200.0 / 255.0]),
            ] {
                let got = px(x, 4);
                for c in 0..3 {
                    assert!(
                        (got[c] - want[c]).abs() < 0.02,
                        "{:?} at {x}: {got:?}",
                        frame.format
                    );
                }
            }
        }
    }

    /// `sample_square` as it read each sample before its offsets were worked
    /// out once a column and row: pixel by pixel, chroma through `chroma_at`.
    fn sample_square_per_pixel(frame: &Frame, square: Square, res: usize) -> Vec<[f32; 3]> {
        let scale = square.side / res as f32;
        let n = (scale.ceil() as usize).clamp(1, 4);
        let at = |start: f32, k: usize, extent: usize| {
            let p = start + (k as f32 + 0.5) * scale / n as f32;
            (p >= 0.0 && p < extent as f32).then_some(p as usize)
        };
        let (x0, y0) = (square.cx - square.side / 2.0, square.cy - square.side / 2.0);
        let p = &frame.planes;
        let mut out = Vec::new();
        for oy in 0..res {
            for ox in 0..res {
                let (mut sum, mut inside) = ([0f32; 3], 0);
                for y in (oy * n..(oy + 1) * n).filter_map(|k| at(y0, k, frame.height)) {
                    for x in (ox * n..(ox + 1) * n).filter_map(|k| at(x0, k, frame.width)) {
                        let v = match frame.format.packed() {
                            Some((offsets, bpp)) => offsets
                                .map(|o| p[0].data[y * p[0].stride + x * bpp + o] as f32 / 255.0),
                            None => {
                                let (cb, cr) = frame.format.chroma_at(p, x, y);
                                [p[0].data[y * p[0].stride + x] as f32, cb as f32, cr as f32]
                            }
                        };
                        sum = [sum[0] + v[0], sum[1] + v[1], sum[2] + v[2]];
                        inside += 1;
                    }
                }
                let mean = sum.map(|s| s / inside.max(1) as f32);
                let rgb = match frame.format.packed() {
                    Some(_) => mean,
                    None => frame.matrix.to_rgb(mean[0], mean[1], mean[2]),
                };
                let share = inside as f32 / (n * n) as f32;
                out.push(rgb.map(|v| v.clamp(0.0, 1.0) * share));
            }
        }
        out
    }

    #[test]
    fn sampling_gives_the_per_pixel_reading_bit_for_bit() {
        let mut noise = crate::frame::test_noise(7);
        for format in crate::frame::ONE_FORMAT_OF_EACH_LAYOUT {
            let owned =
                OwnedFrame::new(format, (203, 117), 5, YuvMatrix::BT601_LIMITED, &mut noise);
            let frame = owned.frame();
            // The detector's letterbox (partly outside), a thumbnail, a square
            // hanging off the corner.
            let squares = [
                (
                    Square {
                        side: 203.0,
                        ..Square::centred(203, 117)
                    },
                    128,
                ),
                (
                    Square {
                        cx: 90.3,
                        cy: 60.7,
                        side: 71.5,
                    },
                    16,
                ),
                (
                    Square {
                        cx: 190.0,
                        cy: 110.0,
                        side: 40.0,
                    },
                    16,
                ),
            ];
            for (square, res) in squares {
                assert_eq!(
                    sample_square(&frame, square, res),
                    sample_square_per_pixel(&frame, square, res),
                    "{format:?} {square:?}"
                );
            }
        }
    }
}
