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
    /// The buffer `detail` moves into when the area moves, kept to spare its
    /// allocation (a fresh one costs a page fault every 4 KiB).
    moved: Vec<f32>,
    /// Variance of the difference of detail between frames where nothing
    /// moves, per band of [`LEVELS`] of the smooth value: a camera's shot
    /// noise grows with the light, so dark hair and a dark room are quieter
    /// than a lit face.
    noise: [Option<f32>; BANDS],
}

/// Buffers kept from channel to channel and frame to frame to spare their
/// allocation. The frame is walked a row at a time, twice, so that what a row
/// needs stays in the cache: whole maps of floats, written in one pass and
/// read in the next, made the denoising as slow as the memory.
#[derive(Default)]
struct Scratch {
    /// The channel's samples over the area, row by row.
    bytes: Vec<u8>,
    /// Local mean squared difference from the frame before, per sample of
    /// the area: the first pass's result, which the second needs with the
    /// noise's level learnt from the whole frame.
    motion: Vec<f32>,
    /// Smooth value per sample of the area, found in the first pass.
    smooth: Vec<f32>,
    /// The last rows' squared differences, by row modulo 3.
    squared: [Vec<f32>; 3],
    /// A row's vertical sums of samples, and of floats.
    sums: Vec<u16>,
    column: Vec<f32>,
    /// Per band of the smooth value, local mean squared differences seen.
    seen: [Vec<f32>; BANDS],
    /// A row's frame x coordinates, results, and the dither of each
    /// row of its pattern.
    xs: Vec<f32>,
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
        let disc = Disc::new(crop, feather, strength);
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
    fn new(crop: Crop, feather: usize, strength: f32) -> Disc {
        let side = crop.size.max(1) as f32;
        Disc {
            centre: [crop.x as f32 + side / 2.0, crop.y as f32 + side / 2.0],
            inner: INNER_RADIUS * side + WHOLE_FADE * feather as f32,
            feather: (1.0 - WHOLE_FADE) * feather as f32,
            strength: strength.clamp(0.0, 1.0),
        }
    }

    /// How much of the denoising shows at each frame point (`xs[i]`, `y`), into `out`.
    #[cfg(test)]
    fn weights(&self, xs: &[f32], y: f32, out: &mut [f32]) {
        let row = self.row(y);
        for (o, &x) in out.iter_mut().zip(xs) {
            *o = row.weight(x);
        }
    }

    /// What the weights along frame row `y` have in common.
    #[inline(always)]
    fn row(&self, y: f32) -> DiscRow<'_> {
        DiscRow {
            disc: self,
            dy: y - self.centre[1],
            scale: 1.0 / self.feather.max(1e-6),
        }
    }

    /// Of the `w` samples from `x0` of a plane's row at frame height `y`,
    /// subsampled by `sub`, the first and the end of those the denoising
    /// shows at: beyond them its weight is 0. Found with a margin of 2
    /// samples, which the rounding of the weights' distances never crosses.
    fn span(&self, y: f32, x0: usize, w: usize, sub: usize) -> (usize, usize) {
        let reach = self.inner + self.feather + 2.0 * sub as f32;
        let dy = y - self.centre[1];
        if dy.abs() >= reach {
            return (0, 0);
        }
        let half = (reach * reach - dy * dy).sqrt();
        // Sample x is at frame x (x0 + x + 0.5) · sub.
        let column = |frame_x: f32| frame_x / sub as f32 - 0.5 - x0 as f32;
        let first = column(self.centre[0] - half).floor().max(0.0) as usize;
        let end = (column(self.centre[0] + half).ceil().max(0.0) as usize + 1).min(w);
        (first.min(end), end)
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

/// The disc along one frame row.
struct DiscRow<'a> {
    disc: &'a Disc,
    /// Distance of the row from the centre, and 1 over the fade's width.
    dy: f32,
    scale: f32,
}

impl DiscRow<'_> {
    /// How much of the denoising shows at frame x `x` of the row.
    #[inline(always)]
    fn weight(&self, x: f32) -> f32 {
        // `fade`, written without branches so that a loop of it vectorises.
        let dx = x - self.disc.centre[0];
        let distance = (dx * dx + self.dy * self.dy).sqrt() - self.disc.inner;
        let t = (1.0 - distance * self.scale).clamp(0.0, 1.0);
        self.disc.strength * t * t * (3.0 - 2.0 * t)
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
        let [_, _, w, h] = area;
        if w == 0 || h == 0 || disc.strength <= 0.0 {
            // Nothing shown: the past no longer matches what is shown next.
            self.detail.clear();
            self.area = [0; 4];
            return;
        }
        self.move_to(area);
        // AVX2, where the CPU has it, doubles the vectors' width of the loops
        // over a row, with the same results: both builds run the same IEEE
        // operations in the same order (see `gain_field::gain_row`).
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.filter_avx2(data, plane, lane, disc, s) };
        }
        self.filter_portable(data, plane, lane, disc, s)
    }

    /// `filter_portable` built for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn filter_avx2(
        &mut self,
        data: &mut [u8],
        plane: &PlaneView,
        lane: usize,
        disc: &Disc,
        s: &mut Scratch,
    ) {
        self.filter_portable(data, plane, lane, disc, s)
    }

    // Always inlined, so that `filter_avx2` holds a copy built for AVX2.
    //
    // The steps, per sample, in the operations (and their order) of a box
    // blur of whole maps (the reference in the tests): the smooth value, a 5
    // × 5 mean of the samples; the detail, the sample less it; its
    // difference from the filtered detail of the frame before, squared (0
    // where there is none); their 3 × 3 mean, the motion; then, with the
    // noise's level that the motion of the whole frame gives, the share of
    // the new detail taken. The first pass finds the motion, the second
    // filters and writes.
    #[inline(always)]
    fn filter_portable(
        &mut self,
        data: &mut [u8],
        plane: &PlaneView,
        lane: usize,
        disc: &Disc,
        s: &mut Scratch,
    ) {
        let [x0, y0, w, h] = self.area;
        let n = w * h;
        s.bytes.resize(n, 0);
        for (y, row) in s.bytes.chunks_exact_mut(w).enumerate() {
            let start = (y0 + y) * plane.stride + x0 * plane.bytes + lane;
            if plane.bytes == 1 {
                row.copy_from_slice(&data[start..start + w]);
            } else {
                let bytes = data[start..].iter().step_by(plane.bytes);
                row.iter_mut().zip(bytes).for_each(|(v, &b)| *v = b);
            }
        }
        s.motion.resize(n, 0.0);
        s.smooth.resize(n, 0.0);
        for buffer in &mut s.squared {
            buffer.resize(w, 0.0);
        }
        s.sums.resize(w, 0);
        s.column.resize(w, 0.0);
        s.seen.iter_mut().for_each(Vec::clear);
        // Every third sample, or fewer in a large area: a quantile of about
        // [`NOISE_SAMPLES`] is plenty, and choosing it costs with its count.
        let step = (n / NOISE_SAMPLES).max(3);
        for y in 0..h {
            let row = y * w..(y + 1) * w;
            let smooth = &mut s.smooth[row.clone()];
            smooth_row(&s.bytes, (w, h), y, &mut s.sums, &mut s.column, smooth);
            for (((squared, &b), &smooth), &past) in (s.squared[y % 3].iter_mut())
                .zip(&s.bytes[row.clone()])
                .zip(&*smooth)
                .zip(&self.detail[row])
            {
                let difference = (b as f32 - smooth) - past;
                *squared = if difference.is_nan() {
                    0.0
                } else {
                    difference * difference
                };
            }
            if y >= MOTION_RADIUS {
                self.motion_row(y - MOTION_RADIUS, (w, h), step, s);
            }
        }
        for y in h.saturating_sub(MOTION_RADIUS)..h {
            self.motion_row(y, (w, h), step, s);
        }
        let Some(noise) = update_noise(&mut self.noise, &mut s.seen) else {
            // Nothing to filter against: the detail is kept, the frame passes.
            for ((past, &b), &smooth) in (self.detail.iter_mut()).zip(&s.bytes).zip(&s.smooth) {
                *past = b as f32 - smooth;
            }
            return;
        };
        // Over the noise, per band: what a local mean squared difference is
        // compared with.
        let inverse = noise.map(|n| 1.0 / n);
        let sub = plane.subsample as f32;
        s.xs.clear();
        s.xs.extend((0..w).map(|x| ((x0 + x) as f32 + 0.5) * sub));
        for (r, row) in s.dither.iter_mut().enumerate() {
            row.clear();
            row.extend((0..w).map(|x| dither(x0 + x, r)));
        }
        s.relit.resize(w, 0.0);
        for y in 0..h {
            let frame_y = ((y0 + y) as f32 + 0.5) * sub;
            // The samples the denoising shows at; elsewhere only the filtered
            // detail changes, the frame's bytes stay as they are.
            let (first, end) = disc.span(frame_y, x0, w, plane.subsample);
            let at = |range: std::ops::Range<usize>| (y * w + range.start)..(y * w + range.end);
            for part in [at(0..first), at(end..w)] {
                for ((past, &b), (&smooth, &motion)) in (self.detail[part.clone()].iter_mut())
                    .zip(&s.bytes[part.clone()])
                    .zip(s.smooth[part.clone()].iter().zip(&s.motion[part]))
                {
                    *past = filtered(*past, b as f32 - smooth, motion, smooth, &inverse);
                }
            }
            if first == end {
                continue;
            }
            let relit = &mut s.relit[first..end];
            let disc_row = disc.row(frame_y);
            let shown = at(first..end);
            let dither = &s.dither[(y0 + y) % DITHER_ROWS][first..end];
            for (((relit, past), (&b, &smooth)), ((&motion, &x), &dither)) in
                (relit.iter_mut().zip(&mut self.detail[shown.clone()]))
                    .zip(s.bytes[shown.clone()].iter().zip(&s.smooth[shown.clone()]))
                    .zip(s.motion[shown].iter().zip(&s.xs[first..end]).zip(dither))
            {
                let v = b as f32;
                let d = v - smooth;
                *past = filtered(*past, d, motion, smooth, &inverse);
                *relit = v + disc_row.weight(x) * (*past - d) + dither;
            }
            let start = (y0 + y) * plane.stride + (x0 + first) * plane.bytes + lane;
            if plane.bytes == 1 {
                let bytes = &mut data[start..start + relit.len()];
                for (b, &r) in bytes.iter_mut().zip(&*relit) {
                    *b = round_to_u8(r);
                }
            } else {
                let bytes = data[start..].iter_mut().step_by(plane.bytes);
                for (b, &r) in bytes.zip(&*relit) {
                    *b = round_to_u8(r);
                }
            }
        }
    }

    /// The motion of row `y` of the area, from the squared differences of
    /// the rows round it, into `s.motion`; and every `step`th sample of the
    /// area's that the frame before had detail at, into `s.seen` by band.
    #[inline(always)]
    fn motion_row(&self, y: usize, (w, h): (usize, usize), step: usize, s: &mut Scratch) {
        const SPAN: usize = 2 * MOTION_RADIUS + 1;
        let (lo, hi) = (
            y.saturating_sub(MOTION_RADIUS),
            (y + MOTION_RADIUS + 1).min(h),
        );
        let scale = 1.0 / (hi - lo) as f32;
        let (column, squared) = (&mut s.column, &s.squared);
        // Added from the top, as the blur of a whole map adds its rows.
        if hi - lo == SPAN {
            let rows: [&[f32]; SPAN] = std::array::from_fn(|r| &squared[(lo + r) % 3][..]);
            for (x, c) in column.iter_mut().enumerate() {
                let mut sum = rows[0][x];
                for row in &rows[1..] {
                    sum += row[x];
                }
                *c = sum * scale;
            }
        } else {
            column.copy_from_slice(&squared[lo % 3]);
            for r in lo + 1..hi {
                (column.iter_mut().zip(&squared[r % 3])).for_each(|(c, v)| *c += v);
            }
            column.iter_mut().for_each(|c| *c *= scale);
        }
        let row = y * w..(y + 1) * w;
        box_row::<SPAN>(&s.column, &mut s.motion[row.clone()]);
        let mut i = row.start.div_ceil(step) * step;
        while i < row.end {
            if !self.detail[i].is_nan() {
                s.seen[band(s.smooth[i])].push(s.motion[i]);
            }
            i += step;
        }
    }

    /// Holds `area` from now on: the filtered detail it shares with the area
    /// held so far is kept, the rest has none yet.
    fn move_to(&mut self, area: [usize; 4]) {
        if self.area == area && !self.detail.is_empty() {
            return;
        }
        let [x0, y0, w, h] = area;
        let [ox, oy, ow, oh] = self.area;
        let moved = &mut self.moved;
        moved.clear();
        moved.resize(w * h, f32::NAN);
        if !self.detail.is_empty() {
            let (left, right) = (x0.max(ox), (x0 + w).min(ox + ow));
            for y in y0.max(oy)..(y0 + h).min(oy + oh) {
                if left < right {
                    let to = (y - y0) * w;
                    let from = (y - oy) * ow;
                    moved[to + left - x0..to + right - x0]
                        .copy_from_slice(&self.detail[from + left - ox..from + right - ox]);
                }
            }
        }
        self.area = area;
        std::mem::swap(&mut self.detail, &mut self.moved);
    }
}

/// The smooth values of row `y` of a `w` × `h` map of `bytes`: their box
/// blur of [`SPLIT_RADIUS`], shrinking at the borders, into `out`; `sums`
/// and `column` hold the vertical pass.
#[inline(always)]
fn smooth_row(
    bytes: &[u8],
    (w, h): (usize, usize),
    y: usize,
    sums: &mut [u16],
    column: &mut [f32],
    out: &mut [f32],
) {
    const SPAN: usize = 2 * SPLIT_RADIUS + 1;
    let (lo, hi) = (
        y.saturating_sub(SPLIT_RADIUS),
        (y + SPLIT_RADIUS + 1).min(h),
    );
    let scale = 1.0 / (hi - lo) as f32;
    // Whole numbers: their sum is exact in any order, as a float or not.
    if hi - lo == SPAN {
        let rows: [&[u8]; SPAN] = std::array::from_fn(|r| &bytes[(lo + r) * w..(lo + r + 1) * w]);
        for (x, c) in column.iter_mut().enumerate() {
            let mut sum = rows[0][x] as u16;
            for row in &rows[1..] {
                sum += row[x] as u16;
            }
            *c = sum as f32 * scale;
        }
    } else {
        let first = &bytes[lo * w..(lo + 1) * w];
        sums.iter_mut().zip(first).for_each(|(s, &b)| *s = b as u16);
        for r in lo + 1..hi {
            let row = &bytes[r * w..(r + 1) * w];
            sums.iter_mut().zip(row).for_each(|(s, &b)| *s += b as u16);
        }
        (column.iter_mut().zip(&*sums)).for_each(|(c, &s)| *c = s as f32 * scale);
    }
    box_row::<SPAN>(column, out);
}

/// A row's horizontal box blur of `SPAN` samples, shrinking at the ends:
/// the window's samples added from the left, then scaled.
#[inline(always)]
fn box_row<const SPAN: usize>(src: &[f32], dst: &mut [f32]) {
    let radius = SPAN / 2;
    let w = src.len();
    if w >= SPAN {
        // Samples with the whole window: dst[k] sums src[k - radius..=k + radius].
        let m = w + 1 - SPAN;
        let inner = &mut dst[radius..radius + m];
        let shifted: [&[f32]; SPAN] = std::array::from_fn(|s| &src[s..s + m]);
        let scale = 1.0 / SPAN as f32;
        for (k, o) in inner.iter_mut().enumerate() {
            let mut sum = shifted[0][k];
            for run in &shifted[1..] {
                sum += run[k];
            }
            *o = sum * scale;
        }
    }
    // The ends' shrunken windows (every sample, in a row narrower than one).
    for k in (0..radius.min(w)).chain(radius.max(w.saturating_sub(radius))..w) {
        let (lo, hi) = (k.saturating_sub(radius), (k + radius + 1).min(w));
        dst[k] = src[lo..hi].iter().sum::<f32>() / (hi - lo) as f32;
    }
}

/// Updates `noise`, the noise's level per band of the smooth value, from the
/// local mean squared differences `seen` in each band of one frame, and
/// returns it for each band; None when no band is known.
fn update_noise(
    noise: &mut [Option<f32>; BANDS],
    seen: &mut [Vec<f32>; BANDS],
) -> Option<[f32; BANDS]> {
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

/// The filtered detail of a sample of detail `d` and smooth value `smooth`,
/// whose filtered detail was `past` (NaN where there was none), at a local
/// mean squared difference `motion`; `inverse` is 1 over the noise per band.
#[inline(always)]
fn filtered(past: f32, d: f32, motion: f32, smooth: f32, inverse: &[f32; BANDS]) -> f32 {
    let difference = d - past;
    let share = new_share(motion * band_value(smooth, inverse));
    let filtered = past + share * difference;
    if difference.is_nan() { d } else { filtered }
}

/// The band of [`LEVELS`] a smooth value lies in.
fn band(smooth: f32) -> usize {
    (smooth.max(0.0) as usize / LEVELS).min(BANDS - 1)
}

/// `per_band[band(smooth)]`, by comparisons rather than an index, so that a
/// loop over samples vectorises: `band` is the count of band starts
/// (whole numbers) that the smooth value reaches.
#[inline(always)]
fn band_value(smooth: f32, per_band: &[f32; BANDS]) -> f32 {
    let mut value = per_band[0];
    for (b, &v) in per_band.iter().enumerate().skip(1) {
        if smooth >= (b * LEVELS) as f32 {
            value = v;
        }
    }
    value
}

/// Share of the new frame's detail at a local mean squared difference of
/// `ratio` times the noise's: [`STILL_SHARE`] up to [`STILL_RATIO`], all of
/// it from [`MOVING_RATIO`], by smoothstep between.
#[inline(always)]
fn new_share(ratio: f32) -> f32 {
    let t = ((ratio - STILL_RATIO) / (MOVING_RATIO - STILL_RATIO)).clamp(0.0, 1.0);
    STILL_SHARE + (1.0 - STILL_SHARE) * t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
