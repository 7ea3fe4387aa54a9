//! Where the denoising shows: the disc round the head that the lighting change
//! covers, whole through its inner circle and part of its fade, then fading
//! out, at the face's strength; and the runs of a row it reaches. The change
//! also runs down the shoulders; they are not denoised, since the face is
//! where the camera's noise, multiplied by the change, shows (a body's
//! clothes and the room beside it take the change with their noise as filmed).

use super::super::Crop;
use super::super::gain_field::INNER_RADIUS;
use super::WHOLE_FADE;

/// Where the denoising shows, in frame pixels.
pub(super) struct Disc {
    centre: [f32; 2],
    inner: f32,
    feather: f32,
    pub(super) strength: f32,
}

impl Disc {
    pub(super) fn new(crop: Crop, feather: usize, strength: f32) -> Disc {
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
    pub(super) fn weights(&self, xs: &[f32], y: f32, out: &mut [f32]) {
        let row = self.row(y);
        for (o, &x) in out.iter_mut().zip(xs) {
            *o = row.weight(x);
        }
    }

    /// What the weights along frame row `y` have in common.
    #[inline(always)]
    pub(super) fn row(&self, y: f32) -> DiscRow<'_> {
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
    pub(super) fn span(&self, y: f32, x0: usize, w: usize, sub: usize) -> (usize, usize) {
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
    pub(super) fn whole_span(&self, y: f32, x0: usize, w: usize, sub: usize) -> (usize, usize) {
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
    pub(super) fn area(&self, sub: usize, size: (usize, usize)) -> [usize; 4] {
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
pub(super) struct DiscRow<'a> {
    disc: &'a Disc,
    /// Distance of the row from the centre, and 1 over the fade's width.
    dy: f32,
    scale: f32,
}

impl DiscRow<'_> {
    /// How much of the denoising shows at frame x `x` of the row.
    #[inline(always)]
    pub(super) fn weight(&self, x: f32) -> f32 {
        // `fade`, written without branches so that a loop of it vectorises.
        let dx = x - self.disc.centre[0];
        let distance = (dx * dx + self.dy * self.dy).sqrt() - self.disc.inner;
        let t = (1.0 - distance * self.scale).clamp(0.0, 1.0);
        self.disc.strength * t * t * (3.0 - 2.0 * t)
    }
}
