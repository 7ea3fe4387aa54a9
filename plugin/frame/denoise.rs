//! The camera's noise taken out of the frame's detail round the face, over
//! time, before the lighting change multiplies it.
//!
//! The lighting change is a smooth gain, so the frame keeps its own detail,
//! and with it the camera's noise: where the change brightens, the noise grows
//! with it, and it differs from frame to frame where the relit truth has none.
//! On the simulator's recordings that noise is nearly all of the element's
//! flicker (README, "Flicker and the source light's detail").
//!
//! Each plane is split into a smooth band (a box blur of [`SPLIT_RADIUS`]) and
//! its detail. The smooth band passes as it is, so a change of the screen's
//! light or a cut shows at once. The detail is filtered recursively, sample
//! by sample: where it differs from the filtered detail of the frame before by
//! about what noise makes it differ, only [`STILL_SHARE`] of the new frame's
//! detail is taken; where it differs by much more (the face moved, or turned),
//! the new detail is taken whole, so a moving face does not leave a trail.
//! The noise's level is learnt from the frames themselves, per band of
//! brightness. The result shows over the disc round the face that the
//! lighting change covers, fading out where the change does, so the noise
//! does not change level at an edge.

use super::gain_field::{INNER_RADIUS, dither};
use super::{Crop, FrameMut, PixelFormat, round_to_u8};

/// Radius, in plane pixels, of the box blur whose rest is the detail that is
/// filtered over time: 5 × 5 samples, which leave a fifth of the noise in
/// the smooth band. A wider split left moving texture in the detail, where it
/// lags (the moving-face test).
const SPLIT_RADIUS: usize = 2;
/// Radius of the local mean of the squared difference from the frame before
/// that tells motion from noise: 3 × 3 samples, so a single noisy sample does
/// not count as motion.
const MOTION_RADIUS: usize = 1;
/// Share of a new frame's detail taken where nothing moved: the filtered
/// detail then averages about the last twelve frames, its noise 0.28 of the
/// frame's.
pub const STILL_SHARE: f32 = 0.15;
/// Local mean squared difference, over the noise's, up to which a sample
/// counts as still ([`STILL_SHARE`]) and from which as moving (taken whole),
/// with a smooth step between. The mean of 9 squared noise differences
/// reaches 2 about once in 30 samples and 6 almost never; higher
/// thresholds held more noise back but left a trail behind texture moving
/// 2 pixels a frame (the moving-face test).
const STILL_RATIO: f32 = 2.0;
const MOVING_RATIO: f32 = 6.0;
/// Share of the lighting change's fade (`feather`) through which the
/// denoising still shows whole; it fades out over the rest. The truth has no
/// noise anywhere, and a change of noise level is a softer edge than one of
/// light.
const WHOLE_FADE: f32 = 0.5;
/// Least variance of the difference of detail between frames, in 8-bit
/// levels squared: about what rounding to whole levels makes alone.
const MIN_NOISE: f32 = 0.2;
/// How much the learnt noise level may rise from one frame to the next, as a
/// share of it (it falls at once): frames where nearly everything moves
/// overestimate the noise, which would then hide the motion. A camera's noise
/// changes with its exposure, over seconds.
const NOISE_RISE: f32 = 0.02;
/// About how many samples a frame the noise's level is learnt from.
const NOISE_SAMPLES: usize = 20_000;
/// Levels (of 256) in each band of the smooth value with its own noise level.
const LEVELS: usize = 32;
const BANDS: usize = 256 / LEVELS;

/// What the denoiser keeps of one channel of one plane: the filtered detail
/// over the plane's part round the face, and the noise's level.
#[derive(Default)]
struct ChannelState {
    /// The part of the plane held: x, y, width, height in plane samples.
    area: [usize; 4],
    /// Filtered detail per sample of `area`, NaN where there is none yet.
    detail: Vec<f32>,
    /// Variance of the difference of detail between frames where nothing
    /// moves, per band of [`LEVELS`] of the smooth value: a camera's shot
    /// noise grows with the light, so dark hair and a dark room are quieter
    /// than a lit face.
    noise: [Option<f32>; BANDS],
}

/// One frame's maps of a channel over its area: buffers kept from channel to
/// channel and frame to frame to spare their allocation.
#[derive(Default)]
struct Scratch {
    values: Vec<f32>,
    smooth: Vec<f32>,
    detail: Vec<f32>,
    difference: Vec<f32>,
    squared: Vec<f32>,
    motion: Vec<f32>,
    /// The vertical pass of a box blur.
    rows: Vec<f32>,
    /// Per band of the smooth value, local mean squared differences seen.
    seen: [Vec<f32>; BANDS],
    /// A row's frame x coordinates, weights, results, and the dither of each
    /// row of its pattern.
    xs: Vec<f32>,
    weight: Vec<f32>,
    relit: Vec<f32>,
    dither: [Vec<f32>; DITHER_ROWS],
}

/// Rows of the ordered dither's pattern (`gain_field::dither`).
const DITHER_ROWS: usize = 4;

/// Temporal denoising of the detail round the face; one per stream.
#[derive(Default)]
pub struct DetailDenoiser {
    /// The stream the state is of: format and frame size.
    stream: Option<(PixelFormat, usize, usize)>,
    /// One per channel, in the order the format's passes walk them.
    channels: Vec<ChannelState>,
    scratch: Scratch,
}

impl DetailDenoiser {
    /// Forgets the past: the next frame passes as it is and starts afresh.
    /// Returns whether there was a past to forget.
    pub fn reset(&mut self) -> bool {
        self.stream = None;
        !std::mem::take(&mut self.channels).is_empty()
    }

    /// Denoises `frame` round `crop`, as far as the lighting change of fade
    /// `feather` reaches: whole through the change's inner circle and
    /// [`WHOLE_FADE`] of its fade, then fading out, at `strength` in [0, 1]
    /// (a face fading in or out).
    pub fn apply(&mut self, frame: &mut FrameMut, crop: Crop, feather: usize, strength: f32) {
        let stream = Some((frame.format, frame.width, frame.height));
        if self.stream != stream {
            self.reset();
            self.stream = stream;
        }
        let side = crop.size.max(1) as f32;
        let disc = Disc {
            centre: [crop.x as f32 + side / 2.0, crop.y as f32 + side / 2.0],
            inner: INNER_RADIUS * side + WHOLE_FADE * feather as f32,
            feather: (1.0 - WHOLE_FADE) * feather as f32,
            strength: strength.clamp(0.0, 1.0),
        };
        let mut k = 0;
        for pass in frame.format.passes() {
            let (data, stride) = (&mut *frame.planes[pass.plane].0, frame.planes[pass.plane].1);
            let sub = pass.subsample;
            let plane = PlaneView {
                size: (frame.width.div_ceil(sub), frame.height.div_ceil(sub)),
                stride,
                bytes: pass.lanes.len(),
                subsample: sub,
            };
            for (lane, channel) in pass.lanes.iter().enumerate() {
                if channel.is_none() {
                    continue;
                }
                if self.channels.len() <= k {
                    self.channels.push(ChannelState::default());
                }
                self.channels[k].filter(data, &plane, lane, &disc, &mut self.scratch);
                k += 1;
            }
        }
    }
}

/// Where the denoising shows, in frame pixels.
struct Disc {
    centre: [f32; 2],
    inner: f32,
    feather: f32,
    strength: f32,
}

impl Disc {
    /// How much of the denoising shows at each frame point (`xs[i]`, `y`), into `out`.
    fn weights(&self, xs: &[f32], y: f32, out: &mut [f32]) {
        let dy = y - self.centre[1];
        // `fade`, written without branches so that the loop vectorises.
        let scale = 1.0 / self.feather.max(1e-6);
        for (o, &x) in out.iter_mut().zip(xs) {
            let dx = x - self.centre[0];
            let distance = (dx * dx + dy * dy).sqrt() - self.inner;
            let t = (1.0 - distance * scale).clamp(0.0, 1.0);
            *o = self.strength * t * t * (3.0 - 2.0 * t);
        }
    }

    /// The plane's samples the disc reaches, subsampled by `sub`, within a
    /// plane of `size`: x, y, width, height.
    fn area(&self, sub: usize, size: (usize, usize)) -> [usize; 4] {
        let reach = self.inner + self.feather;
        let span = |c: f32, extent: usize| {
            let first = (((c - reach) / sub as f32).floor().max(0.0) as usize).min(extent);
            let end = (((c + reach) / sub as f32).ceil().max(0.0) as usize).min(extent);
            (first, end - first)
        };
        let ((x, w), (y, h)) = (span(self.centre[0], size.0), span(self.centre[1], size.1));
        [x, y, w, h]
    }
}

/// One plane's layout.
struct PlaneView {
    /// Samples across and down.
    size: (usize, usize),
    stride: usize,
    /// Bytes a sample (pixel of the plane).
    bytes: usize,
    /// Frame pixels a sample covers each way.
    subsample: usize,
}

impl ChannelState {
    /// Filters byte `lane` of every sample of `plane` that `disc` reaches,
    /// working in `s`.
    fn filter(
        &mut self,
        data: &mut [u8],
        plane: &PlaneView,
        lane: usize,
        disc: &Disc,
        s: &mut Scratch,
    ) {
        let area = disc.area(plane.subsample, plane.size);
        let [x0, y0, w, h] = area;
        if w == 0 || h == 0 || disc.strength <= 0.0 {
            // Nothing shown: the past no longer matches what is shown next.
            self.detail.clear();
            self.area = [0; 4];
            return;
        }
        self.move_to(area);
        let n = w * h;
        // Each step below is a flat loop over whole slices, so that it vectorises.
        s.values.resize(n, 0.0);
        for (y, row) in s.values.chunks_exact_mut(w).enumerate() {
            let start = (y0 + y) * plane.stride + x0 * plane.bytes + lane;
            let bytes = data[start..].iter().step_by(plane.bytes);
            row.iter_mut().zip(bytes).for_each(|(v, &b)| *v = b as f32);
        }
        box_blur(&s.values, (w, h), SPLIT_RADIUS, &mut s.smooth, &mut s.rows);
        // The detail, and its difference from the filtered detail of the
        // frame before: NaN where there is none.
        for buffer in [&mut s.detail, &mut s.difference, &mut s.squared] {
            buffer.resize(n, 0.0);
        }
        for (((d, (&v, &smooth)), difference), past) in (s.detail.iter_mut())
            .zip(s.values.iter().zip(&s.smooth))
            .zip(s.difference.iter_mut())
            .zip(&self.detail)
        {
            *d = v - smooth;
            *difference = *d - past;
        }
        for (squared, &difference) in s.squared.iter_mut().zip(&s.difference) {
            *squared = if difference.is_nan() {
                0.0
            } else {
                difference * difference
            };
        }
        box_blur(
            &s.squared,
            (w, h),
            MOTION_RADIUS,
            &mut s.motion,
            &mut s.rows,
        );
        let Some(noise) = learn_noise(&mut self.noise, s) else {
            self.detail.copy_from_slice(&s.detail);
            return;
        };
        // Over the noise, per band: what a local mean squared difference is
        // compared with. The share of the new frame goes into `squared`.
        let inverse = noise.map(|n| 1.0 / n);
        for (share, (&motion, &smooth)) in s.squared.iter_mut().zip(s.motion.iter().zip(&s.smooth))
        {
            *share = new_share(motion * inverse[band(smooth)]);
        }
        for ((past, &d), (&difference, &share)) in
            (self.detail.iter_mut().zip(&s.detail)).zip(s.difference.iter().zip(&s.squared))
        {
            let filtered = *past + share * difference;
            *past = if difference.is_nan() { d } else { filtered };
        }
        let sub = plane.subsample as f32;
        s.xs.clear();
        s.xs.extend((0..w).map(|x| ((x0 + x) as f32 + 0.5) * sub));
        for (r, row) in s.dither.iter_mut().enumerate() {
            row.clear();
            row.extend((0..w).map(|x| dither(x0 + x, r)));
        }
        s.weight.resize(w, 0.0);
        s.relit.resize(w, 0.0);
        for y in 0..h {
            disc.weights(&s.xs, ((y0 + y) as f32 + 0.5) * sub, &mut s.weight);
            let row = y * w..(y + 1) * w;
            for ((r, (&v, &dither)), ((&filtered, &d), &weight)) in (s.relit.iter_mut())
                .zip(
                    s.values[row.clone()]
                        .iter()
                        .zip(&s.dither[(y0 + y) % DITHER_ROWS]),
                )
                .zip((self.detail[row.clone()].iter().zip(&s.detail[row])).zip(&s.weight))
            {
                *r = v + weight * (filtered - d) + dither;
            }
            let start = (y0 + y) * plane.stride + x0 * plane.bytes + lane;
            let bytes = data[start..].iter_mut().step_by(plane.bytes);
            for (b, &r) in bytes.zip(&s.relit) {
                *b = round_to_u8(r);
            }
        }
    }

    /// Holds `area` from now on: the filtered detail it shares with the area
    /// held so far is kept, the rest has none yet.
    fn move_to(&mut self, area: [usize; 4]) {
        if self.area == area && !self.detail.is_empty() {
            return;
        }
        let [x0, y0, w, h] = area;
        let mut detail = vec![f32::NAN; w * h];
        let [ox, oy, ow, oh] = self.area;
        if !self.detail.is_empty() {
            for y in y0.max(oy)..(y0 + h).min(oy + oh) {
                for x in x0.max(ox)..(x0 + w).min(ox + ow) {
                    detail[(y - y0) * w + x - x0] = self.detail[(y - oy) * ow + x - ox];
                }
            }
        }
        self.area = area;
        self.detail = detail;
    }
}

/// Updates `noise`, the noise's level per band of the smooth value, from one
/// frame's local mean squared differences (`scratch.motion`, over
/// [`MOTION_RADIUS`]) where the frame before had detail, and returns it for
/// each band; None when no sample had a frame before.
fn learn_noise(noise: &mut [Option<f32>; BANDS], scratch: &mut Scratch) -> Option<[f32; BANDS]> {
    let seen = &mut scratch.seen;
    seen.iter_mut().for_each(Vec::clear);
    // Every third sample, or fewer in a large area: a quantile of about
    // [`NOISE_SAMPLES`] is plenty, and choosing it costs with its count.
    let n = scratch.motion.len();
    for i in (0..n).step_by((n / NOISE_SAMPLES).max(3)) {
        if !scratch.difference[i].is_nan() {
            seen[band(scratch.smooth[i])].push(scratch.motion[i]);
        }
    }
    for (noise, seen) in noise.iter_mut().zip(seen.iter_mut()) {
        if seen.len() < 32 {
            continue;
        }
        // A low quantile: in most frames a fifth of what is round a face
        // holds still, whatever moves. The 20th percentile of the mean of 9
        // squared normal variables is 0.598 of their variance.
        let fifth = seen.len() / 5;
        let quantile = *seen.select_nth_unstable_by(fifth, f32::total_cmp).1;
        let estimate = (quantile / 0.598).max(MIN_NOISE);
        *noise = Some(match *noise {
            Some(n) => estimate.min(n * (1.0 + NOISE_RISE)),
            None => estimate,
        });
    }
    // A band with no estimate of its own takes the nearest band's.
    let known: Vec<(usize, f32)> = (noise.iter().enumerate())
        .filter_map(|(b, n)| n.map(|n| (b, n)))
        .collect();
    if known.is_empty() {
        return None;
    }
    Some(std::array::from_fn(|b| {
        known
            .iter()
            .min_by_key(|(k, _)| k.abs_diff(b))
            .map(|&(_, n)| n)
            .expect("at least one band is known")
    }))
}

/// The band of [`LEVELS`] a smooth value lies in.
fn band(smooth: f32) -> usize {
    (smooth.max(0.0) as usize / LEVELS).min(BANDS - 1)
}

/// Share of the new frame's detail at a local mean squared difference of
/// `ratio` times the noise's: [`STILL_SHARE`] up to [`STILL_RATIO`], all of
/// it from [`MOVING_RATIO`], by smoothstep between.
fn new_share(ratio: f32) -> f32 {
    let t = ((ratio - STILL_RATIO) / (MOVING_RATIO - STILL_RATIO)).clamp(0.0, 1.0);
    STILL_SHARE + (1.0 - STILL_SHARE) * t * t * (3.0 - 2.0 * t)
}

/// A box blur of a `w` × `h` map into `out`, `radius` each way, shrinking at
/// the borders; `rows` holds the vertical pass.
fn box_blur(
    field: &[f32],
    (w, h): (usize, usize),
    radius: usize,
    out: &mut Vec<f32>,
    rows: &mut Vec<f32>,
) {
    // Both passes add whole runs of the map shifted against each other, a
    // loop that vectorises, rather than keeping a running sum, whose every
    // step waits for the one before. The radius is small.
    rows.clear();
    rows.resize(field.len(), 0.0);
    for y in 0..h {
        let (lo, hi) = (y.saturating_sub(radius), (y + radius + 1).min(h));
        let sum = &mut rows[y * w..(y + 1) * w];
        for r in lo..hi {
            add_to(sum, &field[r * w..(r + 1) * w]);
        }
        let scale = 1.0 / (hi - lo) as f32;
        sum.iter_mut().for_each(|s| *s *= scale);
    }
    out.clear();
    out.resize(field.len(), 0.0);
    let span = 2 * radius + 1;
    for (src, dst) in rows.chunks_exact(w).zip(out.chunks_exact_mut(w)) {
        if w >= span {
            // Samples with the whole window: dst[k] sums src[k - radius..=k + radius].
            let inner = &mut dst[radius..w - radius];
            for shift in 0..span {
                add_to(inner, &src[shift..shift + w + 1 - span]);
            }
            let scale = 1.0 / span as f32;
            inner.iter_mut().for_each(|s| *s *= scale);
        }
        // The borders' shrunken windows (every sample, in a map narrower than one).
        for k in (0..radius.min(w)).chain(radius.max(w.saturating_sub(radius))..w) {
            let (lo, hi) = (k.saturating_sub(radius), (k + radius + 1).min(w));
            dst[k] = src[lo..hi].iter().sum::<f32>() / (hi - lo) as f32;
        }
    }
}

/// `sum += values`, element by element.
fn add_to(sum: &mut [f32], values: &[f32]) {
    sum.iter_mut().zip(values).for_each(|(s, v)| *s += v);
}

#[cfg(test)]
mod tests;
