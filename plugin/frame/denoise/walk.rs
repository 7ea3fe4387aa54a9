//! The walk over a channel's area round the face, a row at a time: each row
//! read, split into its smooth value and detail, its motion found, then
//! filtered and written back; an area's top and bottom halves on two threads,
//! each in the build for the CPU's vector width, in buffers kept from frame to
//! frame.

use std::ops::Range;

use super::super::gain_field::dither;
use super::super::{FrameMut, Pass, round_to_u8};
use super::channel::{Edges, restored, stored};
use super::disc::Disc;
use super::motion::{filtered, over_noise};
use super::rows::{lane_bytes, set_lane, smooth_row};
use super::{BANDS, Build, MOTION_RADIUS, NOISE_SAMPLES, SPLIT_RADIUS};

/// Buffers kept from channel to channel and frame to frame to spare their
/// allocation; one per thread. The area is walked once, a row at a time, and
/// each step keeps only the few rows round it that the next needs, so that
/// what a row needs stays in the cache: whole maps of floats, written by one
/// step and read by the next, made the denoising as slow as the memory.
#[derive(Default)]
pub(super) struct Scratch {
    /// The channel's samples of the last [`SPLIT_SPAN`] rows read, by row
    /// modulo [`SPLIT_SPAN`]: the smooth value needs them after the frame's
    /// row is written.
    bytes: Vec<u8>,
    /// The last rows' smooth values, by row modulo [`SMOOTH_ROWS`].
    pub(super) smooth: [Vec<f32>; SMOOTH_ROWS],
    /// The last rows' squared differences from the frame before, by row
    /// modulo [`MOTION_SPAN`].
    pub(super) squared: [Vec<f32>; MOTION_SPAN],
    /// A row's local mean squared difference from the frame before.
    pub(super) motion: Vec<f32>,
    /// A row's vertical sums of samples, and of squared differences.
    sums: Vec<u16>,
    pub(super) column: Vec<f32>,
    /// A row's frame x coordinates, how much of the denoising shows at
    /// each, its results, and the dither of each row of its pattern.
    xs: Vec<f32>,
    weight: Vec<f32>,
    relit: Vec<f32>,
    dither: [Vec<f32>; DITHER_ROWS],
}

/// Rows of the box blur that splits off the smooth band, and of the local
/// mean of the motion.
pub(super) const SPLIT_SPAN: usize = 2 * SPLIT_RADIUS + 1;
pub(super) const MOTION_SPAN: usize = 2 * MOTION_RADIUS + 1;
/// Rows of smooth values kept: a row's motion, and so its filtering, waits
/// for the squared differences of the [`MOTION_RADIUS`] rows below it.
pub(super) const SMOOTH_ROWS: usize = MOTION_RADIUS + 1;
/// Rows beyond a row range whose bytes its walk reads: the smooth values of
/// the [`MOTION_RADIUS`] rows beyond it, which its motion needs, need the
/// bytes of [`SPLIT_RADIUS`] more.
pub(super) const EDGE_ROWS: usize = MOTION_RADIUS + SPLIT_RADIUS;

/// What a walk over a channel's area does with each row once its motion is
/// known.
#[derive(Clone, Copy)]
pub(super) enum Walk {
    /// Nothing: the walk only teaches the noise's level.
    Learn,
    /// Keeps the row's detail as it is, with no noise level to filter against.
    Keep,
    /// Filters the row against the noise's level, 1 over it per band.
    Filter([f32; BANDS]),
}

/// Rows of the ordered dither's pattern (`gain_field::dither`).
pub(super) const DITHER_ROWS: usize = 4;

/// Of the `w` samples of a row from `x0`, subsampled by `sub`: their frame x
/// coordinates into `xs`, and per row of the dither's pattern their dither.
pub(super) fn sample_positions(
    x0: usize,
    w: usize,
    sub: usize,
    xs: &mut Vec<f32>,
    dithers: &mut [Vec<f32>; DITHER_ROWS],
) {
    xs.clear();
    xs.extend((0..w).map(|x| ((x0 + x) as f32 + 0.5) * sub as f32));
    for (r, row) in dithers.iter_mut().enumerate() {
        row.clear();
        row.extend((0..w).map(|x| dither(x0 + x, r)));
    }
}

/// Walks `halves` in turn, working in `s`.
pub(super) fn walk_halves(halves: Vec<Half>, disc: &Disc, s: &mut Scratch, build: Build) {
    for half in halves {
        half.walk(disc, s, build);
    }
}

/// One plane's layout.
#[derive(Clone, Copy)]
pub(super) struct PlaneView {
    /// Samples across and down.
    pub(super) size: (usize, usize),
    pub(super) stride: usize,
    /// Bytes a sample (pixel of the plane).
    pub(super) bytes: usize,
    /// Frame pixels a sample covers each way.
    pub(super) subsample: usize,
}

impl PlaneView {
    /// The plane `pass` walks in `frame`.
    pub(super) fn of(frame: &FrameMut, pass: &Pass) -> PlaneView {
        let sub = pass.subsample;
        PlaneView {
            size: (frame.width.div_ceil(sub), frame.height.div_ceil(sub)),
            stride: frame.planes[pass.plane].1,
            bytes: pass.lanes.len(),
            subsample: sub,
        }
    }
}

/// The rows of a plane's area that one thread walks, for each of the
/// plane's channels it walks.
pub(super) struct Half<'a> {
    /// The plane's bytes from row `data_row` on.
    pub(super) data: &'a mut [u8],
    pub(super) data_row: usize,
    pub(super) plane: PlaneView,
    pub(super) channels: Vec<ChannelRows<'a>>,
}

/// One channel's rows of a [`Half`], with what its walk reads and keeps.
pub(super) struct ChannelRows<'a> {
    /// The channel's byte in a sample.
    pub(super) lane: usize,
    /// The channel's whole area, and the rows of it walked.
    pub(super) area: [usize; 4],
    pub(super) rows: Range<usize>,
    /// Filtered detail of `rows`.
    pub(super) detail: &'a mut [i16],
    /// What the walk reads beyond `rows`.
    pub(super) edges: &'a Edges,
    /// The local mean squared differences the walk saw, by band of the
    /// smooth value.
    pub(super) seen: &'a mut [Vec<f32>; BANDS],
    pub(super) walk: Walk,
}

impl Half<'_> {
    /// Walks each channel's rows in turn, working in `s`, in the `build` for
    /// the CPU's vector width (the loops over a row are the compiler's).
    fn walk(self, disc: &Disc, s: &mut Scratch, build: Build) {
        match build {
            Build::Portable => self.walk_portable(disc, s),
            // SAFETY: `Build::available` offers AVX2 only where the CPU has it.
            #[cfg(target_arch = "x86_64")]
            Build::Avx2 => unsafe { self.walk_avx2(disc, s) },
            // SAFETY: `Build::available` offers AVX-512 only where the CPU has
            // F, BW and VL.
            #[cfg(target_arch = "x86_64")]
            Build::Avx512 => unsafe { self.walk_avx512(disc, s) },
        }
    }

    /// `walk_portable` built for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512bw,avx512vl")]
    fn walk_avx512(self, disc: &Disc, s: &mut Scratch) {
        self.walk_portable(disc, s)
    }

    /// `walk_portable` built for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_avx2(self, disc: &Disc, s: &mut Scratch) {
        self.walk_portable(disc, s)
    }

    // Always inlined, so that `walk_avx2` and `walk_avx512` hold copies built
    // for them.
    #[inline(always)]
    fn walk_portable(self, disc: &Disc, s: &mut Scratch) {
        let Half {
            data,
            data_row,
            plane,
            channels,
        } = self;
        for mut rows in channels {
            rows.walk(data, data_row, &plane, disc, s);
        }
    }
}

impl ChannelRows<'_> {
    /// Walks the rows once, in order, doing the `walk` with each once its
    /// motion is known. `data` holds the plane from row `data_row`.
    #[inline(always)]
    fn walk(
        &mut self,
        data: &mut [u8],
        data_row: usize,
        plane: &PlaneView,
        disc: &Disc,
        s: &mut Scratch,
    ) {
        // The steps, per sample, in the operations (and their order) of the
        // plain denoiser in the tests, which works on whole maps: the smooth
        // value, the mean of the 5 × 5 samples round it; the detail, the
        // sample less it; its difference from the filtered detail of the
        // frame before, squared (0 where there is none); their 3 × 3 mean, the
        // motion; then, with the noise's level learnt from the frames before,
        // the share of the new detail taken. A row is filtered and written
        // once the squared differences of the row below it are known; the
        // motion of the rows, sampled every `step`th sample of the area, goes
        // to `seen`.
        let [x0, _, w, h] = self.area;
        s.bytes.resize(SPLIT_SPAN * w, 0);
        for buffer in s.smooth.iter_mut().chain(&mut s.squared) {
            buffer.resize(w, 0.0);
        }
        s.motion.resize(w, 0.0);
        s.sums.resize(w, 0);
        s.column.resize(w, 0.0);
        if let Walk::Filter(_) = self.walk {
            sample_positions(x0, w, plane.subsample, &mut s.xs, &mut s.dither);
            s.relit.resize(w, 0.0);
            s.weight.resize(w, 0.0);
        }
        // Every third sample, or fewer in a large area: a quantile of about
        // [`NOISE_SAMPLES`] is plenty, and choosing it costs with its count.
        let step = (w * h / NOISE_SAMPLES).max(3);
        self.seen.iter_mut().for_each(Vec::clear);
        let Range { start, end } = self.rows;
        // The first row whose squared differences the rows' motion needs.
        let first = start.saturating_sub(MOTION_RADIUS);
        for y in first.saturating_sub(SPLIT_RADIUS)..(first + SPLIT_RADIUS).min(h) {
            self.read_row(y, data, data_row, plane, s);
        }
        for k in first..end + MOTION_RADIUS {
            if k < h {
                if k + SPLIT_RADIUS < h {
                    self.read_row(k + SPLIT_RADIUS, data, data_row, plane, s);
                }
                self.squared_row(k, (w, h), s);
            }
            if k >= start + MOTION_RADIUS {
                let y = k - MOTION_RADIUS;
                self.motion_row(y, (w, h), step, s);
                self.filter_row(y, data, data_row, plane, disc, s);
            }
        }
    }

    /// Copies the channel's bytes of row `y` of the area into the ring of
    /// rows `s.bytes`.
    #[inline(always)]
    fn read_row(&self, y: usize, data: &[u8], data_row: usize, plane: &PlaneView, s: &mut Scratch) {
        let [x0, y0, w, _] = self.area;
        let row = &mut s.bytes[(y % SPLIT_SPAN) * w..][..w];
        if self.rows.contains(&y) {
            let pixels = &data[(y0 + y - data_row) * plane.stride + x0 * plane.bytes..];
            lane_bytes(pixels, plane.bytes, self.lane, row);
        } else {
            row.copy_from_slice(self.edges.bytes(y, w));
        }
    }

    /// The filtered detail of the frame before along row `y` of the area.
    #[inline(always)]
    fn past(&self, y: usize, w: usize) -> &[i16] {
        if self.rows.contains(&y) {
            &self.detail[(y - self.rows.start) * w..][..w]
        } else {
            self.edges.detail(y, w)
        }
    }

    /// The smooth values of row `y` of the area, and its squared differences
    /// from the filtered detail of the frame before (0 where there is none),
    /// into their rings in `s`.
    #[inline(always)]
    fn squared_row(&self, y: usize, (w, h): (usize, usize), s: &mut Scratch) {
        let smooth = &mut s.smooth[y % SMOOTH_ROWS];
        smooth_row(&s.bytes, (w, h), y, &mut s.sums, smooth);
        let bytes = &s.bytes[(y % SPLIT_SPAN) * w..][..w];
        for (((squared, &b), &smooth), &past) in (s.squared[y % MOTION_SPAN].iter_mut())
            .zip(bytes)
            .zip(&*smooth)
            .zip(self.past(y, w))
        {
            let d = b as f32 - smooth;
            let difference = d - restored(past, d);
            *squared = difference * difference;
        }
    }

    /// Does the `walk` with row `y` of the area: filtering, with the
    /// motion in `s.motion`, writes what `disc` shows of the row into the
    /// channel's byte of `data`, the plane from row `data_row`.
    #[inline(always)]
    fn filter_row(
        &mut self,
        y: usize,
        data: &mut [u8],
        data_row: usize,
        plane: &PlaneView,
        disc: &Disc,
        s: &mut Scratch,
    ) {
        let [x0, y0, w, _] = self.area;
        let row = (y - self.rows.start) * w..(y - self.rows.start + 1) * w;
        let bytes = &s.bytes[(y % SPLIT_SPAN) * w..][..w];
        let smooth = &s.smooth[y % SMOOTH_ROWS];
        let inverse = match &self.walk {
            Walk::Learn => return,
            Walk::Keep => {
                for ((past, &b), &smooth) in self.detail[row].iter_mut().zip(bytes).zip(smooth) {
                    *past = stored(b as f32 - smooth);
                }
                return;
            }
            Walk::Filter(inverse) => *inverse,
        };
        let frame_y = ((y0 + y) as f32 + 0.5) * plane.subsample as f32;
        // The samples the denoising shows at; elsewhere only the filtered
        // detail changes, the frame's bytes stay as they are.
        let (first, end) = disc.span(frame_y, x0, w, plane.subsample);
        let detail = &mut self.detail[row];
        let ratio = &mut s.motion;
        over_noise(ratio, smooth, &inverse);
        for part in [0..first, end..w] {
            for ((past, &b), (&smooth, &ratio)) in (detail[part.clone()].iter_mut())
                .zip(&bytes[part.clone()])
                .zip(smooth[part.clone()].iter().zip(&ratio[part]))
            {
                let d = b as f32 - smooth;
                *past = stored(filtered(restored(*past, d), d, ratio));
            }
        }
        if first == end {
            return;
        }
        // How much shows at each sample: the fade's weight, found only
        // outside the run of whole strength round the middle.
        let (whole_first, whole_end) = disc.whole_span(frame_y, x0, w, plane.subsample);
        let whole_first = whole_first.clamp(first, end);
        let whole_end = whole_end.clamp(whole_first, end);
        let disc_row = disc.row(frame_y);
        for part in [first..whole_first, whole_end..end] {
            for (weight, &x) in s.weight[part.clone()].iter_mut().zip(&s.xs[part]) {
                *weight = disc_row.weight(x);
            }
        }
        s.weight[whole_first..whole_end].fill(disc.strength);
        let relit = &mut s.relit[first..end];
        let dither = &s.dither[(y0 + y) % DITHER_ROWS][first..end];
        let shown = first..end;
        for (((relit, past), (&b, &smooth)), ((&ratio, &weight), &dither)) in
            (relit.iter_mut().zip(&mut detail[shown.clone()]))
                .zip(bytes[shown.clone()].iter().zip(&smooth[shown.clone()]))
                .zip(
                    ratio[shown.clone()]
                        .iter()
                        .zip(&s.weight[shown])
                        .zip(dither),
                )
        {
            let v = b as f32;
            let d = v - smooth;
            let filtered = filtered(restored(*past, d), d, ratio);
            *past = stored(filtered);
            *relit = v + weight * (filtered - d) + dither;
        }
        let pixels = &mut data[(y0 + y - data_row) * plane.stride + (x0 + first) * plane.bytes..];
        let lane = self.lane;
        match plane.bytes {
            1 => set_lane::<1>(pixels, 0, relit),
            2 => set_lane::<2>(pixels, lane, relit),
            3 => set_lane::<3>(pixels, lane, relit),
            4 => set_lane::<4>(pixels, lane, relit),
            bytes => {
                let samples = pixels[lane..].iter_mut().step_by(bytes);
                samples.zip(&*relit).for_each(|(b, &r)| *b = round_to_u8(r));
            }
        }
    }
}
