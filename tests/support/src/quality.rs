//! Measures of the element's output that need no ground truth, for real footage
//! (and, beside the exact errors, for the simulator's recordings):
//!
//! - [`box_edge_score`]: the largest straight, axis-aligned step in the smoothed
//!   log ratio of output to input luma that stays coherent over a fifth of
//!   the frame height, in percent: the visible edge of a relit box.
//! - [`mottling`]: the colour part of the per-channel log gain (log gain less its
//!   mean over the channels), less its smooth part (a box blur a quarter of the
//!   face wide), as RMS in percent over the face's pixels of
//!   [`MOTTLING_BLACK`] levels and up, read against the smooth part as an
//!   8-bit output would show it: blotchy skin; [`mottling_in_all`] counts
//!   every pixel, and [`mottling_by_luma`] says which input brightness it
//!   comes from.
//! - [`pumping`]: the 95th percentile of the frame-to-frame change of the face
//!   region's mean (output minus input), in levels, leaving out cuts: brightness
//!   that breathes while the input is steady.
//!
//! The measures read images through [`Pixels`]: packed 8-bit sRGB
//! ([`RgbImage`]), or a frame in the format the element worked in ([`View`]).
//! A Y'CbCr frame is read as it carries light and colour: the box edge on its
//! luma plane, the mottling at the resolution of its chroma planes, both from
//! the 8-bit samples in floating point. Decoded to 8-bit RGB instead, a 4:2:0
//! frame's near-black pixels take colour from the chroma sample they share
//! with brighter ones and are clipped and rounded, which these ratios read as
//! steps and blotches that no change of the element could remove.

use deskstage::monitor::RgbImage;
use gstlsydrelight::face::{CROP_LIFT, CROP_SIDE};
use gstlsydrelight::frame::{Frame, PixelFormat};

/// An image as the measures read it.
pub trait Pixels {
    /// Width and height, in the measure's pixels.
    fn size(&self) -> (usize, usize);
    /// Frame pixels one of the measure's pixels spans along each axis (more
    /// than one where a format carries colour at a lower resolution).
    fn step(&self) -> usize {
        1
    }
    /// R, G and B of pixel (x, y), in [0, 1] (not rounded).
    fn rgb(&self, x: usize, y: usize) -> [f64; 3];
    /// Whether those are 8-bit samples themselves, as any RGB output rounds
    /// them (not so for Y'CbCr, read in floating point from its samples, nor
    /// for luma computed from RGB).
    fn is_8_bit_rgb(&self) -> bool;
}

impl Pixels for RgbImage {
    fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    fn rgb(&self, x: usize, y: usize) -> [f64; 3] {
        let i = 3 * (y * self.width + x);
        [0, 1, 2].map(|c| self.data[i + c] as f64 / 255.0)
    }

    fn is_8_bit_rgb(&self) -> bool {
        true
    }
}

/// A frame in packed RGB or I420, read one of three ways.
#[derive(Clone, Copy)]
pub struct View<'a> {
    frame: Frame<'a>,
    reading: Reading,
}

#[derive(Clone, Copy, PartialEq)]
enum Reading {
    /// Each pixel's RGB; a Y'CbCr pixel with the chroma of the sample it shares.
    Pixels,
    /// Luma alone, as grey: what a Y'CbCr frame carries at full resolution.
    Luma,
    /// One pixel per chroma sample: the mean luma of the pixels it covers,
    /// with its Cb and Cr.
    ChromaSamples,
}

impl<'a> View<'a> {
    fn new(frame: Frame<'a>, reading: Reading) -> View<'a> {
        assert!(
            matches!(frame.format, PixelFormat::Rgb | PixelFormat::I420),
            "the measures read RGB and I420 frames, not {:?}",
            frame.format
        );
        View { frame, reading }
    }

    /// Each pixel in RGB (for images and errors against the truth).
    pub fn pixels(frame: Frame<'a>) -> View<'a> {
        View::new(frame, Reading::Pixels)
    }

    /// What the box edge and the change map read: luma, at full resolution.
    pub fn brightness(frame: Frame<'a>) -> View<'a> {
        View::new(frame, Reading::Luma)
    }

    /// What mottling and mean levels read: colour, at the resolution the
    /// frame's format carries it.
    pub fn colour(frame: Frame<'a>) -> View<'a> {
        View::new(frame, Reading::ChromaSamples)
    }

    fn is_yuv(&self) -> bool {
        self.frame.format == PixelFormat::I420
    }

    fn byte(&self, plane: usize, x: usize, y: usize) -> f32 {
        let p = &self.frame.planes[plane];
        p.data[y * p.stride + x] as f32
    }

    /// R, G and B of 8-bit Y, Cb, Cr as f32, in [0, 1]; negative values (only
    /// from rounding) count as black.
    fn yuv_rgb(&self, luma: f32, cb: f32, cr: f32) -> [f64; 3] {
        self.frame
            .matrix
            .to_rgb(luma, cb, cr)
            .map(|v| v.max(0.0) as f64)
    }

    /// The RGB image of [`View::pixels`], rounded to 8 bits.
    pub fn to_rgb_image(&self) -> RgbImage {
        let (w, h) = self.size();
        RgbImage {
            width: w,
            height: h,
            data: (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .flat_map(|(x, y)| {
                    self.rgb(x, y)
                        .map(|v| (255.0 * v).round().clamp(0.0, 255.0) as u8)
                })
                .collect(),
        }
    }
}

impl Pixels for View<'_> {
    fn is_8_bit_rgb(&self) -> bool {
        !self.is_yuv() && self.reading != Reading::Luma
    }

    fn size(&self) -> (usize, usize) {
        let (w, h) = (self.frame.width, self.frame.height);
        match self.reading {
            Reading::ChromaSamples if self.is_yuv() => (w.div_ceil(2), h.div_ceil(2)),
            _ => (w, h),
        }
    }

    fn step(&self) -> usize {
        if self.reading == Reading::ChromaSamples && self.is_yuv() {
            2
        } else {
            1
        }
    }

    fn rgb(&self, x: usize, y: usize) -> [f64; 3] {
        if !self.is_yuv() {
            let p = &self.frame.planes[0];
            let i = y * p.stride + 3 * x;
            let rgb = [0, 1, 2].map(|c| p.data[i + c] as f64 / 255.0);
            return match self.reading {
                Reading::Luma => [luma(rgb); 3],
                _ => rgb,
            };
        }
        let chroma = |cx, cy| (self.byte(1, cx, cy), self.byte(2, cx, cy));
        match self.reading {
            Reading::Pixels => {
                let (cb, cr) = chroma(x / 2, y / 2);
                self.yuv_rgb(self.byte(0, x, y), cb, cr)
            }
            // Neutral chroma: grey of the pixel's luma.
            Reading::Luma => self.yuv_rgb(self.byte(0, x, y), 128.0, 128.0),
            Reading::ChromaSamples => {
                let (w, h) = (self.frame.width, self.frame.height);
                let (xs, ys) = (2 * x..(2 * x + 2).min(w), 2 * y..(2 * y + 2).min(h));
                let n = (xs.len() * ys.len()) as f32;
                let sum: f32 = ys
                    .flat_map(|py| xs.clone().map(move |px| (px, py)))
                    .map(|(px, py)| self.byte(0, px, py))
                    .sum();
                let (cb, cr) = chroma(x, y);
                self.yuv_rgb(sum / n, cb, cr)
            }
        }
    }
}

/// Added to sRGB values in [0, 1] before taking logs: two levels, so the
/// rounding of near-black pixels does not count as a large ratio.
const LOG_EPSILON: f64 = 2.0 / 255.0;

/// A square region of an image, in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Region {
    pub x: usize,
    pub y: usize,
    pub size: usize,
}

impl Region {
    /// The face inside a square the element relit, by the crop rule
    /// (`gstlsydrelight::face::crop_from_face`) run backwards: a square one
    /// face height across, [`CROP_LIFT`] face heights below the relit square's
    /// centre. The relit square is [`CROP_SIDE`] face heights across and holds
    /// the hair, the neck and the room round the face as well.
    pub fn face_within(self) -> Region {
        let face = self.size as f32 / CROP_SIDE;
        let centre = |start: usize| start as f32 + self.size as f32 / 2.0;
        let corner = |c: f32| (c - face / 2.0).max(0.0).round() as usize;
        Region {
            x: corner(centre(self.x)),
            y: corner(centre(self.y) + CROP_LIFT * face),
            size: (face.round() as usize).max(1),
        }
    }
}

/// Per pixel, row by row: the natural log of output over input of `value(pixel)`.
fn log_ratio(
    input: &impl Pixels,
    output: &impl Pixels,
    value: impl Fn([f64; 3]) -> f64,
) -> Vec<f64> {
    let (w, h) = input.size();
    assert_eq!((w, h), output.size(), "input and output sizes differ");
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let (i, o) = (value(input.rgb(x, y)), value(output.rgb(x, y)));
            ((o + LOG_EPSILON) / (i + LOG_EPSILON)).ln()
        })
        .collect()
}

/// Rec. 709 luma of an sRGB pixel in [0, 1]. Ratios of sRGB values are what a
/// gain applied to the picture changes, whatever the brightness underneath.
pub(crate) fn luma(p: [f64; 3]) -> f64 {
    0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
}

/// `region` (in frame pixels) in the pixels of `image`.
fn in_pixels_of(region: Region, image: &impl Pixels) -> Region {
    let step = image.step();
    Region {
        x: region.x / step,
        y: region.y / step,
        size: region.size.div_ceil(step),
    }
}

/// Box blur of radius `r` (a (2r+1)² box, clipped at the borders) of a w × h field.
fn box_blur(field: &[f64], w: usize, h: usize, r: usize) -> Vec<f64> {
    let pass = |src: &[f64], len: usize, lines: usize, at: &dyn Fn(usize, usize) -> usize| {
        let mut out = vec![0.0; src.len()];
        for line in 0..lines {
            // Running sums along the line.
            let mut prefix = vec![0.0; len + 1];
            for i in 0..len {
                prefix[i + 1] = prefix[i] + src[at(line, i)];
            }
            for i in 0..len {
                let (lo, hi) = (i.saturating_sub(r), (i + r + 1).min(len));
                out[at(line, i)] = (prefix[hi] - prefix[lo]) / (hi - lo) as f64;
            }
        }
        out
    };
    let rows = pass(field, w, h, &|y, x| y * w + x);
    pass(&rows, h, w, &|x, y| y * w + x)
}

/// The largest coherent step of a relit frame's change, and where it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxEdge {
    /// The step, in percent (of the log ratio of output to input luma).
    pub score: f64,
    /// Whether the edge runs vertically (a step across x).
    pub vertical: bool,
    /// Where the step is across the edge (x for a vertical edge, else y), and
    /// where along it the run of a fifth of the frame height starts.
    pub across: usize,
    pub along: usize,
}

/// The box-edge score of a relit frame against its input, in percent.
pub fn box_edge_score(input: &impl Pixels, output: &impl Pixels) -> f64 {
    box_edge(input, output).score
}

/// The smoothed log ratio of output to input luma that [`box_edge_score`] reads.
fn smoothed_change(input: &impl Pixels, output: &impl Pixels) -> (Vec<f64>, usize) {
    // Smoothed over about 1% of the frame height, so noise and texture do not count.
    let (w, h) = input.size();
    let r = (h / 100).max(1);
    (box_blur(&log_ratio(input, output, luma), w, h, r), r)
}

/// The largest coherent step of a relit frame's change against its input.
pub fn box_edge(input: &impl Pixels, output: &impl Pixels) -> BoxEdge {
    let (w, h) = input.size();
    let (ratio, r) = smoothed_change(input, output);
    largest_step(&ratio, None, (w, h), r)
}

/// A relit frame's largest coherent steps: in all ([`box_edge`]), and where
/// the picture itself has none: each step counts less the larger the input's
/// own step in luma at the same place, and not at all from [`PICTURE_EDGE`]
/// up. A true relighting changes a lit face more than the dark room behind
/// it, so its change steps where the face's outline does (the simulator's
/// exact truth scores 12-44% on [`box_edge`] for the presets,
/// `examples/target_lights` `direction`); a box steps across walls and skin
/// alike. The change is smoothed once for both.
pub fn box_edges(input: &impl Pixels, output: &impl Pixels) -> BoxEdges {
    let (w, h) = input.size();
    let (ratio, r) = smoothed_change(input, output);
    let level: Vec<f64> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| (luma(input.rgb(x, y)) + LOG_EPSILON).ln())
        .collect();
    let picture = box_blur(&level, w, h, r);
    BoxEdges {
        all: largest_step(&ratio, None, (w, h), r),
        unexplained: largest_step(&ratio, Some(&picture), (w, h), r),
    }
}

/// A frame's largest box edge in all, and where the picture has none ([`box_edges`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxEdges {
    pub all: BoxEdge,
    pub unexplained: BoxEdge,
}

/// A step of the input's smoothed log luma, across the same distance as the
/// change's, at which a step of the change counts for nothing: a fifth.
pub const PICTURE_EDGE: f64 = 0.2;

/// The largest coherent step of `ratio` (the smoothed change, `r` its blur's
/// radius), each weighted down by the step of `picture` at the same place
/// where one is given.
fn largest_step(
    ratio: &[f64],
    picture: Option<&[f64]>,
    (w, h): (usize, usize),
    r: usize,
) -> BoxEdge {
    let step = 2 * r;
    let run = (h / 5).max(1);
    // Vertical edges: steps across x, averaged along a run of y; horizontal edges
    // likewise with the axes swapped.
    let vertical = coherent_step(ratio, picture, w, h, step, run, |x, y| y * w + x);
    let horizontal = coherent_step(ratio, picture, h, w, step, run, |y, x| y * w + x);
    let (best, is_vertical) = if vertical.0 >= horizontal.0 {
        (vertical, true)
    } else {
        (horizontal, false)
    };
    BoxEdge {
        score: 100.0 * best.0,
        vertical: is_vertical,
        across: best.1,
        along: best.2,
    }
}

/// The change a relit frame makes, as an image: the smoothed log ratio of
/// output to input luma that [`box_edge_score`] reads, mid grey for none,
/// lighter for brighter, black or white at a factor of e^±0.75 (about 2.1).
pub fn change_map(input: &impl Pixels, output: &impl Pixels) -> RgbImage {
    let (ratio, _) = smoothed_change(input, output);
    let (width, height) = input.size();
    RgbImage {
        width,
        height,
        data: ratio
            .iter()
            .flat_map(|v| [(127.5 + 170.0 * v).round().clamp(0.0, 255.0) as u8; 3])
            .collect(),
    }
}

/// The largest mean step `f(a + step) - f(a - step)` across axis `a` (length
/// `across`), averaged over `run` consecutive positions along the other axis;
/// with the `a` and the run's first position where it is. With `picture`,
/// each step is weighted by `1 - |p(a + step) - p(a - step)| / PICTURE_EDGE`
/// (at least 0).
fn coherent_step(
    field: &[f64],
    picture: Option<&[f64]>,
    across: usize,
    along: usize,
    step: usize,
    run: usize,
    at: impl Fn(usize, usize) -> usize,
) -> (f64, usize, usize) {
    let mut best = (0.0, 0, 0);
    if across <= 2 * step || along < run {
        return best;
    }
    let mut steps = vec![0.0; along];
    for a in step..across - step {
        for (b, s) in steps.iter_mut().enumerate() {
            let (hi, lo) = (at(a + step, b), at(a - step, b));
            let weight = picture.map_or(1.0, |p| {
                (1.0 - (p[hi] - p[lo]).abs() / PICTURE_EDGE).max(0.0)
            });
            *s = weight * (field[hi] - field[lo]);
        }
        let mut sum: f64 = steps[..run].iter().sum();
        let mut consider = |sum: f64, first: usize| {
            let mean = sum.abs() / run as f64;
            if mean > best.0 {
                best = (mean, a, first);
            }
        };
        consider(sum, 0);
        for b in run..along {
            sum += steps[b] - steps[b - run];
            consider(sum, b + 1 - run);
        }
    }
    best
}

/// Input luma, in 8-bit levels, below which [`mottling`] counts no pixel.
///
/// An 8-bit output rounds each channel by up to half a level (0.29 RMS), a
/// ratio that grows as the pixel darkens: a perfectly smooth colour change,
/// rounded, already measures about 1.3% of mottling on pixels of 16 levels,
/// 2.4% on pixels of 8 and 6% on pixels of 2 (0.82 of 0.29 / (v + 2): the
/// colour part keeps two thirds of independent noise's variance), so
/// below 16 levels the 2% bar of the real-face tests measures the rounding,
/// not the change. The black of a suit or of a dark film's shadows, a
/// tenth of a face square, then carried nine tenths of the mottling
/// (`docs/real-footage.md`). 16 is also the black of video-range Y'CbCr.
/// Since the mottling reads 8-bit RGB against what rounding allows, the
/// threshold matters most for Y'CbCr, where rounding is not allowed for; in
/// RGB it keeps the measure to the pixels a viewer sees colour in.
pub const MOTTLING_BLACK: f64 = 16.0;

/// Mottling of a relit frame against its input over `face`'s pixels of
/// [`MOTTLING_BLACK`] levels and up, in percent.
pub fn mottling(input: &impl Pixels, output: &impl Pixels, face: Region) -> f64 {
    rms_percent(&mottling_terms(input, output, face, MOTTLING_BLACK))
}

/// Mottling of a relit frame against its input over every pixel of `face`,
/// the near-black ones too, in percent.
pub fn mottling_in_all(input: &impl Pixels, output: &impl Pixels, face: Region) -> f64 {
    rms_percent(&mottling_terms(input, output, face, 0.0))
}

/// RMS over the pixels and channels of per-pixel sums over the channels, in percent.
fn rms_percent(terms: &[(usize, f64)]) -> f64 {
    let sum: f64 = terms.iter().map(|(_, t)| t).sum();
    100.0 * (sum / (3 * terms.len()).max(1) as f64).sqrt()
}

/// Where a frame's mottling comes from: per band of the input's luma (in
/// levels, `edges` rising: below the first, between each two, from the last
/// up), the band's share of the pixels of `face` and of the mottling's sum of
/// squares, both in [0, 1].
pub fn mottling_by_luma(
    input: &impl Pixels,
    output: &impl Pixels,
    face: Region,
    edges: &[f64],
) -> Vec<(f64, f64)> {
    let terms = mottling_terms(input, output, face, 0.0);
    let w = input.size().0;
    let mut bands = vec![(0.0, 0.0); edges.len() + 1];
    for &(i, t) in &terms {
        let level = 255.0 * luma(input.rgb(i % w, i / w));
        let band = edges.partition_point(|&e| e <= level);
        bands[band].0 += 1.0;
        bands[band].1 += t;
    }
    let (count, sum) = (
        terms.len().max(1) as f64,
        terms.iter().map(|(_, t)| t).sum::<f64>(),
    );
    bands
        .into_iter()
        .map(|(n, t)| (n / count, if sum > 0.0 { t / sum } else { 0.0 }))
        .collect()
}

/// Per pixel of `face` (in frame pixels; its index in the image's pixels)
/// whose input luma is `black` levels or more: the squares, summed over the
/// channels, of the colour part (the channel's less the mean of the three) of
/// its per-channel log gain less the smooth gain's (a box blur a quarter of
/// the face wide, over all its pixels).
///
/// The smooth gain is read as the output would show it: applied to the input
/// pixel and clipped to the 8-bit range, and in 8-bit RGB rounded, so that a
/// sample within half a level of it departs by nothing. Rounding and clipping
/// are what any output makes of any change, not the change: a gain that
/// darkens a dark channel to a few levels makes half a level a large ratio
/// there, and a saturated shadow's blue channel, 1 level taken below black,
/// reads as black whatever the gain. The film clip darkened by one gain per
/// channel, smooth everywhere, read 5.1-6.4% of mottling against the plain
/// blur of its log gain, unrounded (`docs/real-footage.md`, "The measures").
/// Y'CbCr is read as before: no rounding allowed for, every sample alike.
fn mottling_terms(
    input: &impl Pixels,
    output: &impl Pixels,
    face: Region,
    black: f64,
) -> Vec<(usize, f64)> {
    let (w, h) = input.size();
    let face = in_pixels_of(face, input);
    let channel_gain = |c: usize| log_ratio(input, output, |p| p[c]);
    let gains = [channel_gain(0), channel_gain(1), channel_gain(2)];
    let radius = (face.size / 8).max(1);
    let pixels: Vec<usize> = (face.y..(face.y + face.size).min(h))
        .flat_map(|y| (face.x..(face.x + face.size).min(w)).map(move |x| y * w + x))
        .filter(|&i| 255.0 * luma(input.rgb(i % w, i / w)) >= black)
        .collect();
    let rgb_8_bit = output.is_8_bit_rgb();
    let smooth = if rgb_8_bit {
        smooth_8_bit_gains(&gains, output, w, h, radius)
    } else {
        gains.each_ref().map(|g| box_blur(g, w, h, radius))
    };
    // How far rounding to 8 bits may have moved an output sample, and the
    // range it can show. Y'CbCr read in RGB may pass white, and from below
    // black it reads as black only where its RGB does; its reading is the old
    // measure's, the log gain less its blur, exactly.
    let (rounding, range) = if rgb_8_bit {
        (0.5 / 255.0, (0.0, 1.0))
    } else {
        (0.0, (f64::NEG_INFINITY, f64::INFINITY))
    };
    pixels
        .into_iter()
        .map(|i| {
            let (inp, out) = (input.rgb(i % w, i / w), output.rgb(i % w, i / w));
            // Per channel, the output's log ratio to the nearest value that the
            // smooth gain's output, clipped and rounded, could have become.
            let departure = [0, 1, 2].map(|c| {
                let expected = (smooth[c][i].exp() * (inp[c] + LOG_EPSILON) - LOG_EPSILON)
                    .clamp(range.0, range.1);
                let nearest = out[c].clamp(expected - rounding, expected + rounding);
                ((out[c] + LOG_EPSILON) / (nearest + LOG_EPSILON)).ln()
            });
            let mean = departure.iter().sum::<f64>() / 3.0;
            (i, departure.iter().map(|d| (d - mean) * (d - mean)).sum())
        })
        .collect()
}

/// Per channel, the smooth part of the log gains `gains` of an 8-bit RGB
/// `output` (w × h): their blur of `radius`, each sample weighted by how
/// precisely it reads the gain, the square of its output level plus
/// [`LOG_EPSILON`] (rounding's error in the log ratio falls as the level
/// rises), and not at all where the output is clipped. A dark shadow's
/// rounded and clipped blue channels then do not pull their neighbours'
/// smooth gain off theirs. The smooth part follows the well-exposed pixels
/// more than a plain blur does, so a change that differs between dark and
/// bright pixels reads a little more (the simulator's `steady`, 0.30% to
/// 0.38% over the face). Where nothing within the blur can be read, the
/// sample's own gain counts as smooth.
fn smooth_8_bit_gains(
    gains: &[Vec<f64>; 3],
    output: &impl Pixels,
    w: usize,
    h: usize,
    radius: usize,
) -> [Vec<f64>; 3] {
    let levels: Vec<[f64; 3]> = (0..w * h).map(|i| output.rgb(i % w, i / w)).collect();
    [0, 1, 2].map(|c| {
        let weight: Vec<f64> = levels
            .iter()
            .map(|rgb| {
                let out = rgb[c];
                if (0.5 / 255.0..254.5 / 255.0).contains(&out) {
                    (out + LOG_EPSILON) * (out + LOG_EPSILON)
                } else {
                    0.0
                }
            })
            .collect();
        let weighted: Vec<f64> = gains[c].iter().zip(&weight).map(|(g, w)| g * w).collect();
        let (sum, total) = (
            box_blur(&weighted, w, h, radius),
            box_blur(&weight, w, h, radius),
        );
        sum.iter()
            .zip(total)
            .zip(&gains[c])
            .map(|((s, t), g)| if t > 0.0 { s / t } else { *g })
            .collect()
    })
}

/// A change of the input's face-region mean, in levels, that counts as a cut.
const CUT_LEVELS: f64 = 8.0;

/// Mean over `face` (in frame pixels) of all three channels, in 8-bit levels.
pub fn mean_level(img: &impl Pixels, face: Region) -> f64 {
    let (w, h) = img.size();
    let face = in_pixels_of(face, img);
    let (mut sum, mut count) = (0.0, 0usize);
    for y in face.y..(face.y + face.size).min(h) {
        for x in face.x..(face.x + face.size).min(w) {
            sum += img.rgb(x, y).iter().sum::<f64>();
            count += 3;
        }
    }
    255.0 * sum / count.max(1) as f64
}

/// One frame's part in [`pumping`]: the relit square's mean level in the
/// input and in the output, and whether the element showed its change only in
/// part there (a face fading in or out, `Relit::shown` under 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SquareMeans {
    pub input: f64,
    pub output: f64,
    pub fading: bool,
}

impl SquareMeans {
    /// The output's mean less the input's: what the relighting added.
    fn change(&self) -> f64 {
        self.output - self.input
    }
}

/// The 95th percentile of the frame-to-frame change of the output's face-region
/// mean less the input's, in levels. Left out: steps where the input's mean
/// jumps by [`CUT_LEVELS`] (a cut), and steps into or out of a frame whose
/// change was fading. A face found fades its change in over the element's
/// fade, by design; counted, a fade's steps are the clip's largest and rise
/// with the relighting's strength, so a stronger effect would read as pumping.
pub fn pumping(frames: &[SquareMeans]) -> f64 {
    let mut steps: Vec<f64> = frames
        .windows(2)
        .filter(|p| (p[1].input - p[0].input).abs() < CUT_LEVELS)
        .filter(|p| !p[0].fading && !p[1].fading)
        .map(|p| (p[1].change() - p[0].change()).abs())
        .collect();
    if steps.is_empty() {
        return 0.0;
    }
    steps.sort_by(f64::total_cmp);
    steps[((steps.len() - 1) as f64 * 0.95).round() as usize]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [u8; 3]) -> RgbImage {
        RgbImage {
            width: w,
            height: h,
            data: (0..w * h).flat_map(|i| f(i % w, i / w)).collect(),
        }
    }

    #[test]
    fn the_face_within_a_relit_square_is_the_crop_rule_backwards() {
        // A face 100 px high centred at (155, 187) gets a 290 px square
        // centred 22 px above it.
        let square = Region {
            x: 10,
            y: 20,
            size: 290,
        };
        assert_eq!(
            square.face_within(),
            Region {
                x: 105,
                y: 137,
                size: 100
            }
        );
    }

    #[test]
    fn a_brightened_box_scores_high_and_a_smooth_gain_low() {
        let (w, h) = (320, 240);
        let input = image(w, h, |x, y| [(x % 100) as u8 + 50, (y % 90) as u8 + 50, 90]);
        let boxed = image(w, h, |x, y| {
            let p = [(x % 100) as u8 + 50, (y % 90) as u8 + 50, 90];
            if (80..240).contains(&x) {
                p.map(|v| v.saturating_add(40))
            } else {
                p
            }
        });
        let smooth = image(w, h, |x, y| {
            let p = [(x % 100) as u8 + 50, (y % 90) as u8 + 50, 90];
            p.map(|v| (v as f64 * (1.0 + 0.3 * x as f64 / w as f64)).round() as u8)
        });
        let boxed_score = box_edge_score(&input, &boxed);
        let smooth_score = box_edge_score(&input, &smooth);
        assert!(boxed_score > 30.0, "{boxed_score}");
        assert!(smooth_score < 5.0, "{smooth_score}");
        assert!(box_edge_score(&input, &input) < 1e-9);
        // The box steps across the picture's flat parts: unexplained too.
        assert!(box_edges(&input, &boxed).unexplained.score > 30.0);
    }

    #[test]
    fn a_lit_face_on_a_dark_wall_steps_where_the_picture_does() {
        // A bright square "face" on a dark wall, the face brightened by a
        // third and the wall by a tenth: the change steps at the face's
        // outline, which the picture explains; the same step on a flat
        // picture is a box.
        let (w, h) = (320, 240);
        let face = |x: usize, y: usize| (100..220).contains(&x) && (40..200).contains(&y);
        let scene = |x: usize, y: usize| if face(x, y) { [180; 3] } else { [30; 3] };
        let lit = |x: usize, y: usize| if face(x, y) { [240; 3] } else { [33; 3] };
        let (input, output) = (image(w, h, scene), image(w, h, lit));
        let edges = box_edges(&input, &output);
        assert!(edges.all.score > 15.0);
        assert!(edges.unexplained.score < 1.0);
        let flat = image(w, h, |_, _| [120; 3]);
        let boxed = image(w, h, |x, y| if face(x, y) { [160; 3] } else { [132; 3] });
        assert!(box_edges(&flat, &boxed).unexplained.score > 15.0);
    }

    #[test]
    fn colour_blotches_mottle_and_an_even_tint_does_not() {
        let (w, h) = (128, 128);
        let face = Region {
            x: 32,
            y: 32,
            size: 64,
        };
        let input = image(w, h, |_, _| [150, 120, 100]);
        let tinted = image(w, h, |_, _| [165, 120, 95]);
        let blotched = image(w, h, |x, y| {
            if (x / 4 + y / 4) % 2 == 0 {
                [170, 112, 100]
            } else {
                [140, 128, 100]
            }
        });
        assert!(mottling(&input, &tinted, face) < 0.5);
        assert!(mottling(&input, &blotched, face) > 5.0);
        // All of it from the one band the face's pixels lie in.
        let bands = mottling_by_luma(&input, &blotched, face, &[16.0, 64.0, 200.0]);
        assert_eq!(bands.len(), 4);
        assert_eq!(bands[2], (1.0, 1.0));
    }

    #[test]
    fn rounding_a_smooth_change_on_near_black_pixels_is_not_mottling() {
        let (w, h) = (128, 128);
        let face = whole(128);
        // A textured face whose lower three eighths are a near-black collar, given
        // a smooth warm change and rounded to 8 bits, as any output is.
        let level = |x: usize, y: usize, base: usize| (base + (x * 7 + y * 13) % 11) as f64;
        let input = image(w, h, |x, y| {
            let v = if y >= 80 {
                level(x, y, 1)
            } else {
                level(x, y, 120)
            };
            [v as u8, (0.8 * v) as u8, (0.7 * v) as u8]
        });
        let warm = |x: usize, y: usize| {
            let gain = [1.12, 1.0, 0.9].map(|g: f64| g * (1.0 + 0.002 * x as f64));
            let p = input.data[3 * (y * w + x)..][..3].to_vec();
            [0, 1, 2].map(|c| (p[c] as f64 * gain[c]).round().min(255.0) as u8)
        };
        let relit = image(w, h, warm);
        // Read against the unrounded smooth gain, as the measure once did, the
        // collar's rounding alone was over the 2% bar; now it is under half of
        // it even counting the collar (a pure gain, which the measure's 2
        // levels read as a little change on near-black pixels).
        assert!(mottling_in_all(&input, &relit, face) < 1.0);
        assert!(mottling(&input, &relit, face) < 0.5);
        // Blotches on pixels just above the black still count, at twice the
        // bar and more (less the half level that rounding may have made).
        let dim = image(w, h, |x, y| [level(x, y, 24) as u8; 3]);
        let blotched = image(w, h, |x, y| {
            let v = level(x, y, 24) as u8;
            if (x / 4 + y / 4) % 2 == 0 {
                [v + 5, v, v]
            } else {
                [v, v, v + 5]
            }
        });
        assert!(mottling(&dim, &blotched, face) > 4.0);
    }

    /// The whole of a `size` × `size` image as the face region.
    fn whole(size: usize) -> Region {
        Region { x: 0, y: 0, size }
    }

    #[test]
    fn a_strong_smooth_darkening_of_dark_skin_is_not_mottling_and_blotches_on_it_are() {
        // Dark, warm, textured skin (a dim film's face, its blue channel 4-15
        // levels under a luma of about 50), each channel darkened by one gain
        // (the element's gain, (v' + 2) = g (v + 2)) and rounded to 8 bits:
        // perfectly smooth, yet its blue channel falls to a few levels, where
        // half a level is a large ratio. Read against the unrounded smooth
        // gain, as the measure once did, it mottled by 2.5%.
        let (w, h) = (128, 128);
        let face = whole(128);
        // Skin's texture, irregular as a camera's is.
        let texture = |x: usize, y: usize| (((x * 73_856_093) ^ (y * 19_349_663)) % 23) as f64;
        let input = image(w, h, |x, y| {
            let t = texture(x, y);
            [70.0 + t, 45.0 + 0.7 * t, 4.0 + 0.5 * t].map(|v| v as u8)
        });
        let darken = |p: [u8; 3], gain: [f64; 3]| {
            [0, 1, 2].map(|c| {
                (gain[c] * (p[c] as f64 + 2.0) - 2.0)
                    .round()
                    .clamp(0.0, 255.0) as u8
            })
        };
        let smooth = image(w, h, |x, y| darken(input.pixel(x, y), [0.8, 0.69, 0.54]));
        assert!(mottling(&input, &smooth, face) < 0.3);
        // The same darkening in blotches of a tenth either way still counts.
        let blotched = image(w, h, |x, y| {
            let shift = if (x / 4 + y / 4) % 2 == 0 { 1.1 } else { 0.9 };
            darken(input.pixel(x, y), [0.8 * shift, 0.69, 0.54 / shift])
        });
        assert!(mottling(&input, &blotched, face) > 5.0);
    }

    #[test]
    fn i420_is_read_as_it_carries_light_and_colour() {
        use gstlsydrelight::frame::{OwnedFrame, YuvMatrix};
        // A 4 x 2 I420 frame: a dark pixel beside three bright ones in the
        // first chroma sample, whose colour is a saturated red; grey beside it.
        let mut frame = OwnedFrame::new(
            PixelFormat::I420,
            (4, 2),
            0,
            YuvMatrix::BT601_LIMITED,
            || 128,
        );
        frame.planes[0].0 = vec![20, 200, 120, 120, 200, 200, 120, 120];
        frame.planes[1].0 = vec![100, 128];
        frame.planes[2].0 = vec![200, 128];
        let f = frame.frame();
        // Pixel by pixel the dark one's green and blue fall below black and clip.
        let dark = View::pixels(f).rgb(0, 0);
        assert!(dark[1] == 0.0 && dark[2] == 0.0, "{dark:?}");
        // Its chroma sample is read as one pixel: the mean luma of the four
        // with their colour, which no channel clips.
        let colour = View::colour(f);
        assert_eq!((colour.size(), colour.step()), ((2, 1), 2));
        let sample = colour.rgb(0, 0);
        let expected = YuvMatrix::BT601_LIMITED.to_rgb(155.0, 100.0, 200.0);
        for c in 0..3 {
            assert!(sample[c] > 0.0 && (sample[c] - expected[c] as f64).abs() < 1e-6);
        }
        // Brightness is the luma plane, as grey: (120 - 16) / 219.
        let grey = View::brightness(f).rgb(2, 1);
        assert!(
            grey.iter().all(|&v| (v - 104.0 / 219.0).abs() < 1e-6),
            "{grey:?}"
        );
    }

    #[test]
    fn pumping_is_the_95th_percentile_step_between_cuts_and_fades() {
        let frame = |input: f64, output: f64| SquareMeans {
            input,
            output,
            fading: false,
        };
        let steady = vec![frame(100.0, 103.0); 40];
        assert_eq!(pumping(&steady), 0.0);
        let breathing: Vec<SquareMeans> = (0..40)
            .map(|i| frame(100.0, if i % 10 < 5 { 100.0 } else { 107.0 }))
            .collect();
        assert!((pumping(&breathing) - 7.0).abs() < 1e-9);
        // A cut moves input and output together by 50 levels: not pumping.
        let cut: Vec<SquareMeans> = (0..40)
            .map(|i| {
                if i < 20 {
                    frame(100.0, 103.0)
                } else {
                    frame(150.0, 160.0)
                }
            })
            .collect();
        assert_eq!(pumping(&cut), 0.0);
        // A face's change fading in by 2 levels a frame over 15 frames, then
        // steady: the fade is not pumping; breathing after it is.
        let mut fade_in: Vec<SquareMeans> = (0..40)
            .map(|i| SquareMeans {
                fading: i < 15,
                ..frame(100.0, 100.0 + 2.0 * i.min(15) as f64)
            })
            .collect();
        assert_eq!(pumping(&fade_in), 0.0);
        for (i, later) in fade_in.iter_mut().enumerate().skip(15) {
            later.output += if i % 10 < 5 { 0.0 } else { 3.0 };
        }
        assert!((pumping(&fade_in) - 3.0).abs() < 1e-9);
    }
}
