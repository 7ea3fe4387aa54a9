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
//! brightness, each frame filtered against what the frames before it taught:
//! a camera's noise changes over seconds, and so each frame is walked once.
//! The result shows over the disc round the face that the lighting change
//! covers, fading out where the change does, so the noise does not change
//! level at an edge.

use std::ops::Range;

use super::gain_field::{INNER_RADIUS, dither};
use super::{Crop, FrameMut, Pass, PixelFormat, round_to_u8};
use crate::parallel::beside;

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
    /// Filtered detail per sample of `area` ([`stored`]), [`NO_DETAIL`]
    /// where there is none yet.
    detail: Vec<i16>,
    /// The buffer `detail` moves into when the area moves, kept to spare its
    /// allocation (a fresh one costs a page fault every 4 KiB).
    moved: Vec<i16>,
    /// Variance of the difference of detail between frames where nothing
    /// moves, per band of [`LEVELS`] of the smooth value: a camera's shot
    /// noise grows with the light, so dark hair and a dark room are quieter
    /// than a lit face.
    noise: [Option<f32>; BANDS],
    /// Per half of the area (top, bottom), the local mean squared
    /// differences its walk saw, by band of the smooth value. The noise's
    /// level is learnt from the top's followed by the bottom's: what one walk
    /// over the whole area would have seen, in the same order.
    seen: [[Vec<f32>; BANDS]; 2],
    /// Per half of the area, the rows beyond it that its walk reads.
    edges: [Edges; 2],
}

/// Rows beyond one half of an area that its walk reads and the other half's
/// thread writes: copies of them taken before either thread starts.
#[derive(Default)]
struct Edges {
    /// Rows of the area whose bytes (of the channel's lane) `bytes` holds.
    byte_rows: Range<usize>,
    bytes: Vec<u8>,
    /// Rows of the area whose filtered detail `detail` holds.
    detail_rows: Range<usize>,
    detail: Vec<i16>,
}

impl Edges {
    fn bytes(&self, y: usize, w: usize) -> &[u8] {
        debug_assert!(self.byte_rows.contains(&y), "row {y} was not copied");
        &self.bytes[(y - self.byte_rows.start) * w..][..w]
    }

    fn detail(&self, y: usize, w: usize) -> &[i16] {
        debug_assert!(self.detail_rows.contains(&y), "row {y} was not copied");
        &self.detail[(y - self.detail_rows.start) * w..][..w]
    }
}

/// Buffers kept from channel to channel and frame to frame to spare their
/// allocation; one per thread. The area is walked once, a row at a time, and
/// each step keeps only the few rows round it that the next needs, so that
/// what a row needs stays in the cache: whole maps of floats, written by one
/// step and read by the next, made the denoising as slow as the memory.
#[derive(Default)]
struct Scratch {
    /// The channel's samples of the last [`SPLIT_SPAN`] rows read, by row
    /// modulo [`SPLIT_SPAN`]: the smooth value needs them after the frame's
    /// row is written.
    bytes: Vec<u8>,
    /// The last rows' smooth values, by row modulo [`SMOOTH_ROWS`].
    smooth: [Vec<f32>; SMOOTH_ROWS],
    /// The last rows' squared differences from the frame before, by row
    /// modulo [`MOTION_SPAN`].
    squared: [Vec<f32>; MOTION_SPAN],
    /// A row's local mean squared difference from the frame before.
    motion: Vec<f32>,
    /// A row's vertical sums of samples, and of squared differences.
    sums: Vec<u16>,
    column: Vec<f32>,
    /// A row's frame x coordinates, how much of the denoising shows at
    /// each, its results, and the dither of each row of its pattern.
    xs: Vec<f32>,
    weight: Vec<f32>,
    relit: Vec<f32>,
    dither: [Vec<f32>; DITHER_ROWS],
}

/// Rows of the box blur that splits off the smooth band, and of the local
/// mean of the motion.
const SPLIT_SPAN: usize = 2 * SPLIT_RADIUS + 1;
const MOTION_SPAN: usize = 2 * MOTION_RADIUS + 1;
/// Rows of smooth values kept: a row's motion, and so its filtering, waits
/// for the squared differences of the [`MOTION_RADIUS`] rows below it.
const SMOOTH_ROWS: usize = MOTION_RADIUS + 1;
/// Rows beyond a row range whose bytes its walk reads: the smooth values of
/// the [`MOTION_RADIUS`] rows beyond it, which its motion needs, need the
/// bytes of [`SPLIT_RADIUS`] more.
const EDGE_ROWS: usize = MOTION_RADIUS + SPLIT_RADIUS;

/// Samples of the areas of a frame's channels from which each area is walked
/// in two halves, on two threads. A sample takes about 3 ns; splitting saves
/// half the walk and costs handing the half to another thread (about 20 µs,
/// `paste_speed`'s last line; about 0.1 ms when each split started a thread), so it
/// pays from about 13,000 samples. Kept higher, where the gain is sure.
const SPLIT_FROM: usize = 65_536;

/// What a walk over a channel's area does with each row once its motion is
/// known.
#[derive(Clone, Copy)]
enum Walk {
    /// Nothing: the walk only teaches the noise's level.
    Learn,
    /// Keeps the row's detail as it is, with no noise level to filter against.
    Keep,
    /// Filters the row against the noise's level, 1 over it per band.
    Filter([f32; BANDS]),
}

/// Which walk a pass over the frame's channels does.
#[derive(Clone, Copy, PartialEq)]
enum Phase {
    /// Teaches the noise's level to the channels that have none yet.
    Learn,
    /// Filters every channel shown (or keeps its detail, with no noise level).
    Denoise,
}

/// Rows of the ordered dither's pattern (`gain_field::dither`).
const DITHER_ROWS: usize = 4;

/// Of the `w` samples of a row from `x0`, subsampled by `sub`: their frame x
/// coordinates into `xs`, and per row of the dither's pattern their dither.
fn sample_positions(
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

/// Temporal denoising of the detail round the face; one per stream.
pub struct DetailDenoiser {
    /// The stream the state is of: format and frame size.
    stream: Option<(PixelFormat, usize, usize)>,
    /// One per channel, in the order the format's passes walk them.
    channels: Vec<ChannelState>,
    scratch: Scratch,
    /// The scratch of the other thread, which walks the areas' bottom halves.
    second: Scratch,
    /// [`SPLIT_FROM`]; the tests split every area.
    split_from: usize,
    /// The build of the walk this CPU runs; the tests run each it can.
    build: Build,
}

/// A build of the walk, for the vector width the CPU has. Every build runs
/// the same IEEE operations in the same order, so all give the same bytes
/// (see `gain_field::gain_row`); a wider one does more samples at a time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Build {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512 F, BW and VL: 16 floats a vector, twice AVX2's.
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Build {
    /// The builds this CPU can run, the widest last.
    fn available() -> Vec<Build> {
        let mut builds = vec![Build::Portable];
        builds.extend(Build::vector_builds());
        builds
    }

    /// The builds for this CPU's vector extensions.
    #[cfg(target_arch = "x86_64")]
    fn vector_builds() -> Vec<Build> {
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        [(avx2, Build::Avx2), (super::has_avx512(), Build::Avx512)]
            .into_iter()
            .filter_map(|(has, build)| has.then_some(build))
            .collect()
    }

    #[cfg(not(target_arch = "x86_64"))]
    fn vector_builds() -> Vec<Build> {
        Vec::new()
    }

    fn widest() -> Build {
        *Build::available()
            .last()
            .expect("the portable build is always there")
    }
}

impl Default for DetailDenoiser {
    fn default() -> DetailDenoiser {
        DetailDenoiser {
            stream: None,
            channels: Vec::new(),
            scratch: Scratch::default(),
            second: Scratch::default(),
            split_from: SPLIT_FROM,
            build: Build::widest(),
        }
    }
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
        let passes = frame.format.passes();
        let planes: Vec<PlaneView> = (passes.iter())
            .flat_map(|pass| {
                let plane = PlaneView::of(frame, pass);
                pass.lanes.iter().flatten().map(move |_| plane)
            })
            .collect();
        self.channels
            .resize_with(planes.len(), ChannelState::default);
        for (channel, plane) in self.channels.iter_mut().zip(&planes) {
            let area = disc.area(plane.subsample, plane.size);
            if area[2] == 0 || area[3] == 0 || disc.strength <= 0.0 {
                // Nothing shown: the past no longer matches what is shown next.
                channel.detail.clear();
                channel.area = [0; 4];
            } else {
                channel.move_to(area);
            }
        }
        // In a stream's first frames no noise level is learnt yet: the frame
        // teaches it first, so that the first with a past is filtered.
        if (self.channels.iter()).any(|c| c.walks(Phase::Learn)) {
            self.walk_channels(frame, &disc, Phase::Learn);
        }
        self.walk_channels(frame, &disc, Phase::Denoise);
    }

    /// Walks the channels that `phase` walks, each area's top half on this
    /// thread and its bottom half on another (the whole area here, where
    /// the frame's areas are too small to split), then learns the noise's
    /// level from what each walk saw.
    fn walk_channels(&mut self, frame: &mut FrameMut, disc: &Disc, phase: Phase) {
        let walks: Vec<bool> = self.channels.iter().map(|c| c.walks(phase)).collect();
        let samples: usize = (self.channels.iter().zip(&walks))
            .filter(|(_, walks)| **walks)
            .map(|(c, _)| c.area[2] * c.area[3])
            .sum();
        let split = samples >= self.split_from;
        let passes = frame.format.passes();
        let views: Vec<PlaneView> = passes.iter().map(|p| PlaneView::of(frame, p)).collect();
        let mut planes = frame.planes.each_mut().map(Some);
        let mut channels = self.channels.iter_mut().zip(&walks);
        let [mut tops, mut bottoms] = [Vec::new(), Vec::new()];
        for (pass, plane) in passes.iter().zip(views) {
            let (data, _) = planes[pass.plane].take().expect("a plane a pass");
            let mut lanes = Vec::new();
            for (lane, _) in pass.lanes.iter().enumerate().filter(|(_, c)| c.is_some()) {
                let (channel, walks) = channels.next().expect("a channel a lane");
                if *walks {
                    lanes.push((lane, channel));
                }
            }
            let Some((_, first)) = lanes.first() else {
                continue;
            };
            // The plane's channels hold the same area.
            let [_, y0, _, h] = first.area;
            let mid = if split && h >= 2 { h / 2 } else { h };
            let walk = |c: &ChannelState| match phase {
                Phase::Learn => Walk::Learn,
                Phase::Denoise => match per_band(&c.noise) {
                    Some(noise) => Walk::Filter(noise.map(|n| 1.0 / n)),
                    None => Walk::Keep,
                },
            };
            let (mut top, mut bottom) = (Vec::new(), Vec::new());
            for (lane, channel) in lanes {
                if mid < h {
                    channel.copy_edges(data, &plane, lane, mid);
                }
                let walk = walk(channel);
                let ChannelState {
                    area,
                    detail,
                    seen,
                    edges,
                    ..
                } = channel;
                let (top_detail, bottom_detail) = detail.split_at_mut(mid * area[2]);
                let [top_seen, bottom_seen] = seen;
                let [top_edges, bottom_edges] = &*edges;
                top.push(ChannelRows {
                    lane,
                    area: *area,
                    rows: 0..mid,
                    detail: top_detail,
                    edges: top_edges,
                    seen: top_seen,
                    walk,
                });
                if mid < h {
                    bottom.push(ChannelRows {
                        lane,
                        area: *area,
                        rows: mid..h,
                        detail: bottom_detail,
                        edges: bottom_edges,
                        seen: bottom_seen,
                        walk,
                    });
                }
            }
            let at = ((y0 + mid) * plane.stride).min(data.len());
            let (top_data, bottom_data) = data.split_at_mut(at);
            tops.push(Half {
                data: top_data,
                data_row: 0,
                plane,
                channels: top,
            });
            if !bottom.is_empty() {
                bottoms.push(Half {
                    data: bottom_data,
                    data_row: y0 + mid,
                    plane,
                    channels: bottom,
                });
            }
        }
        let (scratch, second, build) = (&mut self.scratch, &mut self.second, self.build);
        if bottoms.is_empty() {
            walk_halves(tops, disc, scratch, build);
        } else {
            beside(
                || walk_halves(bottoms, disc, second, build),
                || walk_halves(tops, disc, scratch, build),
            );
        }
        for (channel, _) in (self.channels.iter_mut().zip(&walks)).filter(|(_, w)| **w) {
            let [top, bottom] = &mut channel.seen;
            top.iter_mut().zip(bottom).for_each(|(t, b)| t.append(b));
            learn_noise(&mut channel.noise, top);
        }
    }
}

/// Walks `halves` in turn, working in `s`.
fn walk_halves(halves: Vec<Half>, disc: &Disc, s: &mut Scratch, build: Build) {
    for half in halves {
        half.walk(disc, s, build);
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

    /// Of the same samples, the first and the end of a run the denoising
    /// shows at whole strength: within the inner circle, where `weight` is
    /// exactly `strength`. Found with a margin of 2 samples inwards.
    fn whole_span(&self, y: f32, x0: usize, w: usize, sub: usize) -> (usize, usize) {
        let radius = self.inner - 2.0 * sub as f32;
        let dy = y - self.centre[1];
        if dy.abs() >= radius {
            return (0, 0);
        }
        let half = (radius * radius - dy * dy).sqrt();
        let column = |frame_x: f32| frame_x / sub as f32 - 0.5 - x0 as f32;
        let first = (column(self.centre[0] - half).ceil().max(0.0) as usize).min(w);
        let end = ((column(self.centre[0] + half).floor() + 1.0).max(0.0) as usize).min(w);
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
#[derive(Clone, Copy)]
struct PlaneView {
    /// Samples across and down.
    size: (usize, usize),
    stride: usize,
    /// Bytes a sample (pixel of the plane).
    bytes: usize,
    /// Frame pixels a sample covers each way.
    subsample: usize,
}

impl PlaneView {
    /// The plane `pass` walks in `frame`.
    fn of(frame: &FrameMut, pass: &Pass) -> PlaneView {
        let sub = pass.subsample;
        PlaneView {
            size: (frame.width.div_ceil(sub), frame.height.div_ceil(sub)),
            stride: frame.planes[pass.plane].1,
            bytes: pass.lanes.len(),
            subsample: sub,
        }
    }
}

impl ChannelState {
    /// Whether `phase` walks this channel: one the disc reaches, and to
    /// learn the noise's level, one that has none yet.
    fn walks(&self, phase: Phase) -> bool {
        let shown = self.area[2] > 0 && self.area[3] > 0;
        shown && (phase == Phase::Denoise || per_band(&self.noise).is_none())
    }

    /// Copies into `edges` what each half of the area, split at row `mid`,
    /// reads beyond it: of `data`, the plane whose byte `lane` the channel
    /// is, [`EDGE_ROWS`] rows; of the filtered detail, [`MOTION_RADIUS`].
    fn copy_edges(&mut self, data: &[u8], plane: &PlaneView, lane: usize, mid: usize) {
        let [x0, y0, w, h] = self.area;
        let below = |rows: usize| mid..(mid + rows).min(h);
        let above = |rows: usize| mid.saturating_sub(rows)..mid;
        let beyond = [
            (below(EDGE_ROWS), below(MOTION_RADIUS)),
            (above(EDGE_ROWS), above(MOTION_RADIUS)),
        ];
        for (edges, (byte_rows, detail_rows)) in self.edges.iter_mut().zip(beyond) {
            edges.bytes.resize(byte_rows.len() * w, 0);
            for (y, out) in byte_rows.clone().zip(edges.bytes.chunks_exact_mut(w)) {
                let pixels = &data[(y0 + y) * plane.stride + x0 * plane.bytes..];
                lane_bytes(pixels, plane.bytes, lane, out);
            }
            edges.detail.clear();
            (edges.detail)
                .extend_from_slice(&self.detail[detail_rows.start * w..detail_rows.end * w]);
            (edges.byte_rows, edges.detail_rows) = (byte_rows, detail_rows);
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
        moved.resize(w * h, NO_DETAIL);
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

/// The rows of a plane's area that one thread walks, for each of the
/// plane's channels it walks.
struct Half<'a> {
    /// The plane's bytes from row `data_row` on.
    data: &'a mut [u8],
    data_row: usize,
    plane: PlaneView,
    channels: Vec<ChannelRows<'a>>,
}

/// One channel's rows of a [`Half`], with what its walk reads and keeps.
struct ChannelRows<'a> {
    /// The channel's byte in a sample.
    lane: usize,
    /// The channel's whole area, and the rows of it walked.
    area: [usize; 4],
    rows: Range<usize>,
    /// Filtered detail of `rows`.
    detail: &'a mut [i16],
    /// What the walk reads beyond `rows`.
    edges: &'a Edges,
    /// The local mean squared differences the walk saw, by band of the
    /// smooth value.
    seen: &'a mut [Vec<f32>; BANDS],
    walk: Walk,
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

    /// The motion of row `y` of the area, from the squared differences of
    /// the rows round it, into `s.motion`; and every `step`th sample of the
    /// area's that the frame before had detail at, into `seen` by band.
    #[inline(always)]
    fn motion_row(&mut self, y: usize, (w, h): (usize, usize), step: usize, s: &mut Scratch) {
        let (lo, hi) = (
            y.saturating_sub(MOTION_RADIUS),
            (y + MOTION_RADIUS + 1).min(h),
        );
        let scale = 1.0 / (hi - lo) as f32;
        let (column, squared) = (&mut s.column, &s.squared);
        // Added from the top, as the blur of a whole map adds its rows.
        if hi - lo == MOTION_SPAN {
            let rows: [&[f32]; MOTION_SPAN] =
                std::array::from_fn(|r| &squared[(lo + r) % MOTION_SPAN][..]);
            for (x, c) in column.iter_mut().enumerate() {
                let mut sum = rows[0][x];
                for row in &rows[1..] {
                    sum += row[x];
                }
                *c = sum * scale;
            }
        } else {
            column.copy_from_slice(&squared[lo % MOTION_SPAN]);
            for r in lo + 1..hi {
                (column.iter_mut().zip(&squared[r % MOTION_SPAN])).for_each(|(c, v)| *c += v);
            }
            column.iter_mut().for_each(|c| *c *= scale);
        }
        box_row::<MOTION_SPAN>(&s.column, &mut s.motion);
        let smooth = &s.smooth[y % SMOOTH_ROWS];
        // The samples are chosen by their index in the whole area, so that
        // the halves see together what one walk over it would.
        let row = y * w..(y + 1) * w;
        let offset = self.rows.start * w;
        let mut i = row.start.div_ceil(step) * step;
        while i < row.end {
            if self.detail[i - offset] != NO_DETAIL {
                let x = i - row.start;
                self.seen[band(smooth[x])].push(s.motion[x]);
            }
            i += step;
        }
    }
}

/// Byte `lane` of each of the first `out.len()` samples of `bytes` bytes of
/// `pixels`, into `out`.
#[inline(always)]
fn lane_bytes(pixels: &[u8], bytes: usize, lane: usize, out: &mut [u8]) {
    // With the sample's size known to the compiler, the loop picks bytes out
    // of whole vectors of pixels rather than one at a time.
    match bytes {
        1 => out.copy_from_slice(&pixels[..out.len()]),
        2 => lane_of::<2>(pixels, lane, out),
        3 => lane_of::<3>(pixels, lane, out),
        4 => lane_of::<4>(pixels, lane, out),
        bytes => {
            let samples = pixels[lane..].iter().step_by(bytes);
            out.iter_mut().zip(samples).for_each(|(v, &b)| *v = b);
        }
    }
}

/// Byte `lane` of each of the first `out.len()` samples of `BYTES` bytes
/// of `pixels`, into `out`.
#[inline(always)]
fn lane_of<const BYTES: usize>(pixels: &[u8], lane: usize, out: &mut [u8]) {
    // Samples of 2 and 4 bytes are read as whole words and the lane shifted
    // down: a shift and a narrowing a vector. Picked by index, the compiler
    // sometimes gathered the bytes one at a time (one `vpinsrb` each), which
    // made BGRx's denoising 10% slower or not by the build's luck.
    let shift = 8 * lane;
    match BYTES {
        2 => {
            for (v, p) in out.iter_mut().zip(pixels.chunks_exact(2)) {
                *v = (u16::from_le_bytes([p[0], p[1]]) >> shift) as u8;
            }
        }
        4 => {
            for (v, p) in out.iter_mut().zip(pixels.chunks_exact(4)) {
                *v = (u32::from_le_bytes([p[0], p[1], p[2], p[3]]) >> shift) as u8;
            }
        }
        _ => {
            for (v, pixel) in out.iter_mut().zip(pixels.chunks_exact(BYTES)) {
                *v = pixel[lane];
            }
        }
    }
}

/// Byte `lane` of each of the first `values.len()` samples of `BYTES` bytes
/// of `pixels`: the value rounded.
#[inline(always)]
fn set_lane<const BYTES: usize>(pixels: &mut [u8], lane: usize, values: &[f32]) {
    // As `lane_of`: samples of 2 and 4 bytes are rewritten as whole words,
    // the lane masked in, so the loop stores vectors, not a byte at a time.
    let shift = 8 * lane;
    match BYTES {
        2 => {
            let keep = !(0xffu16 << shift);
            for (pixel, &r) in pixels.chunks_exact_mut(2).zip(values) {
                let word = u16::from_le_bytes([pixel[0], pixel[1]]);
                let word = word & keep | u16::from(round_to_u8(r)) << shift;
                pixel.copy_from_slice(&word.to_le_bytes());
            }
        }
        4 => {
            let keep = !(0xffu32 << shift);
            for (pixel, &r) in pixels.chunks_exact_mut(4).zip(values) {
                let word = u32::from_le_bytes([pixel[0], pixel[1], pixel[2], pixel[3]]);
                let word = word & keep | u32::from(round_to_u8(r)) << shift;
                pixel.copy_from_slice(&word.to_le_bytes());
            }
        }
        _ => {
            for (pixel, &r) in pixels.chunks_exact_mut(BYTES).zip(values) {
                pixel[lane] = round_to_u8(r);
            }
        }
    }
}

/// The smooth values of row `y` of a `w` × `h` map, whose rows round it
/// `ring` holds by row modulo [`SPLIT_SPAN`]: the mean of the samples within
/// [`SPLIT_RADIUS`] each way, the window shrinking at the borders, into
/// `out`; `sums` holds the vertical sums. The sums are of whole numbers,
/// exact in any order, and scaled once.
#[inline(always)]
fn smooth_row(ring: &[u8], (w, h): (usize, usize), y: usize, sums: &mut [u16], out: &mut [f32]) {
    let (lo, hi) = (
        y.saturating_sub(SPLIT_RADIUS),
        (y + SPLIT_RADIUS + 1).min(h),
    );
    let rows = hi - lo;
    let row = |r: usize| &ring[(r % SPLIT_SPAN) * w..][..w];
    if rows == SPLIT_SPAN {
        let rows: [&[u8]; SPLIT_SPAN] = std::array::from_fn(row);
        for (x, s) in sums.iter_mut().enumerate() {
            let mut sum = rows[0][x] as u16;
            for row in &rows[1..] {
                sum += row[x] as u16;
            }
            *s = sum;
        }
    } else {
        sums.iter_mut()
            .zip(row(lo))
            .for_each(|(s, &b)| *s = b as u16);
        for r in lo + 1..hi {
            sums.iter_mut()
                .zip(row(r))
                .for_each(|(s, &b)| *s += b as u16);
        }
    }
    let mean = |sum: u16, columns: usize| sum as f32 * (1.0 / (rows * columns) as f32);
    if w >= SPLIT_SPAN {
        // Samples with the whole window: out[k] sums sums[k - radius..=k + radius].
        let m = w + 1 - SPLIT_SPAN;
        let shifted: [&[u16]; SPLIT_SPAN] = std::array::from_fn(|s| &sums[s..s + m]);
        for (k, o) in out[SPLIT_RADIUS..SPLIT_RADIUS + m].iter_mut().enumerate() {
            let mut sum = shifted[0][k];
            for run in &shifted[1..] {
                sum += run[k];
            }
            *o = mean(sum, SPLIT_SPAN);
        }
    }
    // The ends' shrunken windows (every sample, in a row narrower than one).
    for k in (0..SPLIT_RADIUS.min(w)).chain(SPLIT_RADIUS.max(w.saturating_sub(SPLIT_RADIUS))..w) {
        let (first, end) = (
            k.saturating_sub(SPLIT_RADIUS),
            (k + SPLIT_RADIUS + 1).min(w),
        );
        out[k] = mean(sums[first..end].iter().sum(), end - first);
    }
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

/// Filtered detail kept as a whole number of 1/[`DETAIL_STEPS`] of a level:
/// half the memory of a float, which the denoising's time follows, the
/// detail being larger than the caches and read and written every frame. A
/// 128th of a level is far below what the rounding of the result to whole
/// levels shows, and the largest detail, 255 levels, still fits.
const DETAIL_STEPS: f32 = 128.0;
/// The detail kept where there is none yet.
const NO_DETAIL: i16 = i16::MIN;

/// `detail` (under 256 levels either way) as it is kept.
#[inline(always)]
fn stored(detail: f32) -> i16 {
    // Adding 1.5 · 2^23 leaves nothing below the units, so the sum is the
    // steps rounded to the nearest whole number, ties to even, and the low
    // 16 bits of the sum's bits are that number in two's complement (those of
    // 1.5 · 2^23 are 0). The steps stay within ±32640, never `NO_DETAIL`.
    const SHIFT: f32 = 12_582_912.0;
    (detail * DETAIL_STEPS + SHIFT).to_bits() as i16
}

/// The detail `stored` keeps as `kept`; where there is none, the sample's
/// new detail `d`: it then differs by nothing, which counts as no motion,
/// and the new detail is taken whole.
#[inline(always)]
fn restored(kept: i16, d: f32) -> f32 {
    if kept == NO_DETAIL {
        d
    } else {
        kept as f32 * (1.0 / DETAIL_STEPS)
    }
}

/// Updates `noise`, the noise's level per band of the smooth value, from the
/// local mean squared differences `seen` in each band of one frame.
fn learn_noise(noise: &mut [Option<f32>; BANDS], seen: &mut [Vec<f32>; BANDS]) {
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
}

/// The noise's level for each band, a band with no estimate of its own
/// taking the nearest band's; None when no band is known.
fn per_band(noise: &[Option<f32>; BANDS]) -> Option<[f32; BANDS]> {
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

/// The filtered detail of a sample of detail `d` whose filtered detail was
/// `past` (`restored`), at a local mean squared difference `ratio` times the
/// noise's level.
#[inline(always)]
fn filtered(past: f32, d: f32, ratio: f32) -> f32 {
    past + new_share(ratio) * (d - past)
}

/// The band of [`LEVELS`] a smooth value lies in.
fn band(smooth: f32) -> usize {
    (smooth.max(0.0) as usize / LEVELS).min(BANDS - 1)
}

/// Each of a row's local mean squared differences `motion` over the noise's
/// level at its smooth value, `inverse` being 1 over the noise per band.
#[inline(always)]
fn over_noise(motion: &mut [f32], smooth: &[f32], inverse: &[f32; BANDS]) {
    // Chosen at run time in every build of the walk, the portable one too.
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { over_noise_avx2(motion, smooth, inverse) };
    }
    over_noise_plain(motion, smooth, inverse);
}

/// `over_noise` a sample at a time.
#[inline(always)]
fn over_noise_plain(motion: &mut [f32], smooth: &[f32], inverse: &[f32; BANDS]) {
    for (m, &s) in motion.iter_mut().zip(smooth) {
        *m *= inverse[band(s)];
    }
}

/// `over_noise` with AVX2: the band's value is picked by a permutation of a
/// vector that holds one band a lane, where the compiler, from an index,
/// picks one sample at a time. The same band and product: the smooth value
/// times 1/[`LEVELS`] (a power of two, so exact) truncated is `band`'s.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn over_noise_avx2(motion: &mut [f32], smooth: &[f32], inverse: &[f32; BANDS]) {
    use std::arch::x86_64::*;
    const LANES: usize = 8;
    const { assert!(BANDS == LANES && LEVELS.is_power_of_two()) };
    let n = motion.len().min(smooth.len());
    let (motion, smooth) = (&mut motion[..n], &smooth[..n]);
    let last_band = _mm256_set1_epi32(BANDS as i32 - 1);
    let per_level = _mm256_set1_ps(1.0 / LEVELS as f32);
    // SAFETY: each load and store reads or writes 8 floats of a slice of 8
    // (`inverse`, or a chunk of 8).
    unsafe {
        let table = _mm256_loadu_ps(inverse.as_ptr());
        for (m, s) in (motion.chunks_exact_mut(LANES)).zip(smooth.chunks_exact(LANES)) {
            let s = _mm256_max_ps(_mm256_loadu_ps(s.as_ptr()), _mm256_setzero_ps());
            let b = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_mul_ps(s, per_level)), last_band);
            let over = _mm256_mul_ps(
                _mm256_loadu_ps(m.as_ptr()),
                _mm256_permutevar8x32_ps(table, b),
            );
            _mm256_storeu_ps(m.as_mut_ptr(), over);
        }
    }
    let done = n - n % LANES;
    over_noise_plain(&mut motion[done..], &smooth[done..], inverse);
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
