//! What the denoiser keeps of each channel from frame to frame: the filtered
//! detail over the plane's part round the face, held as whole numbers of a
//! fraction of a level, and the noise's level; with the rows beyond each half
//! of the area that the two halves' walks read from each other.

use std::ops::Range;

use super::motion::per_band;
use super::rows::lane_bytes;
use super::walk::{EDGE_ROWS, PlaneView};
use super::{BANDS, MOTION_RADIUS, Phase};

/// What the denoiser keeps of one channel of one plane: the filtered detail
/// over the plane's part round the face, and the noise's level.
#[derive(Default)]
pub(super) struct ChannelState {
    /// The part of the plane held: x, y, width, height in plane samples.
    pub(super) area: [usize; 4],
    /// Filtered detail per sample of `area` ([`stored`]), [`NO_DETAIL`]
    /// where there is none yet.
    pub(super) detail: Vec<i16>,
    /// The buffer `detail` moves into when the area moves, kept to spare its
    /// allocation (a fresh one costs a page fault every 4 KiB).
    moved: Vec<i16>,
    /// Variance of the difference of detail between frames where nothing
    /// moves, per band of [`LEVELS`](super::LEVELS) of the smooth value: a
    /// camera's shot noise grows with the light, so dark hair and a dark room
    /// are quieter than a lit face.
    pub(super) noise: [Option<f32>; BANDS],
    /// Per half of the area (top, bottom), the local mean squared
    /// differences its walk saw, by band of the smooth value. The noise's
    /// level is learnt from the top's followed by the bottom's: what one walk
    /// over the whole area would have seen, in the same order.
    pub(super) seen: [[Vec<f32>; BANDS]; 2],
    /// Per half of the area, the rows beyond it that its walk reads.
    pub(super) edges: [Edges; 2],
}

/// Rows beyond one half of an area that its walk reads and the other half's
/// thread writes: copies of them taken before either thread starts.
#[derive(Default)]
pub(super) struct Edges {
    /// Rows of the area whose bytes (of the channel's lane) `bytes` holds.
    byte_rows: Range<usize>,
    bytes: Vec<u8>,
    /// Rows of the area whose filtered detail `detail` holds.
    detail_rows: Range<usize>,
    detail: Vec<i16>,
}

impl Edges {
    pub(super) fn bytes(&self, y: usize, w: usize) -> &[u8] {
        debug_assert!(self.byte_rows.contains(&y), "row {y} was not copied");
        &self.bytes[(y - self.byte_rows.start) * w..][..w]
    }

    pub(super) fn detail(&self, y: usize, w: usize) -> &[i16] {
        debug_assert!(self.detail_rows.contains(&y), "row {y} was not copied");
        &self.detail[(y - self.detail_rows.start) * w..][..w]
    }
}

impl ChannelState {
    /// Whether `phase` walks this channel: one the disc reaches, and to
    /// learn the noise's level, one that has none yet.
    pub(super) fn walks(&self, phase: Phase) -> bool {
        let shown = self.area[2] > 0 && self.area[3] > 0;
        shown && (phase == Phase::Denoise || per_band(&self.noise).is_none())
    }

    /// Copies into `edges` what each half of the area, split at row `mid`,
    /// reads beyond it: of `data`, the plane whose byte `lane` the channel
    /// is, [`EDGE_ROWS`] rows; of the filtered detail, [`MOTION_RADIUS`].
    pub(super) fn copy_edges(&mut self, data: &[u8], plane: &PlaneView, lane: usize, mid: usize) {
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
    pub(super) fn move_to(&mut self, area: [usize; 4]) {
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

/// Filtered detail kept as a whole number of 1/[`DETAIL_STEPS`] of a level:
/// half the memory of a float, which the denoising's time follows, the
/// detail being larger than the caches and read and written every frame. A
/// 128th of a level is far below what the rounding of the result to whole
/// levels shows, and the largest detail, 255 levels, still fits.
const DETAIL_STEPS: f32 = 128.0;
/// The detail kept where there is none yet.
pub(super) const NO_DETAIL: i16 = i16::MIN;

/// `detail` (under 256 levels either way) as it is kept.
#[inline(always)]
pub(super) fn stored(detail: f32) -> i16 {
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
pub(super) fn restored(kept: i16, d: f32) -> f32 {
    if kept == NO_DETAIL {
        d
    } else {
        kept as f32 * (1.0 / DETAIL_STEPS)
    }
}
