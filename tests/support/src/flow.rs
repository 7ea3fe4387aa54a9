//! Classical optical flow, and the temporal measure built on it that needs no
//! network weights: tOF (TecoGAN's, Chu et al. 2020), the mean length of the
//! difference between the flow of consecutive output frames and the flow of the
//! consecutive ground-truth frames. A relit video whose face moves as the truth
//! moves scores near 0; flicker, swimming or lagging relighting make the flow of
//! the output differ from the truth's.
//!
//! The flow is Horn and Schunck's (1981), coarse to fine over an image pyramid
//! with the second image warped by the flow so far at each level, on the Rec. 601
//! luma in [0, 1] blurred a little first (a 5-tap binomial filter), so that the
//! camera's noise is not read as motion.

use deskstage::monitor::RgbImage;

/// Weight of the flow's smoothness against brightness constancy (intensities in [0, 1]).
const SMOOTHNESS: f32 = 0.02;
/// Jacobi iterations at each pyramid level.
const ITERATIONS: usize = 40;
/// The coarsest level is at least this many pixels on its shorter side.
const COARSEST: usize = 24;

/// A single-channel image.
#[derive(Clone, Debug)]
pub struct Gray {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl Gray {
    /// The Rec. 601 luma of a square region (x, y, size) of an RGB image, in [0, 1].
    pub fn luma(img: &RgbImage, region: (usize, usize, usize)) -> Gray {
        let (x0, y0, size) = region;
        let (width, height) = (size.min(img.width - x0), size.min(img.height - y0));
        let mut data = Vec::with_capacity(width * height);
        for y in y0..y0 + height {
            for x in x0..x0 + width {
                let p = &img.data[(y * img.width + x) * 3..][..3];
                data.push(
                    (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32) / 255.0,
                );
            }
        }
        Gray {
            width,
            height,
            data,
        }
    }

    fn at(&self, x: isize, y: isize) -> f32 {
        let x = x.clamp(0, self.width as isize - 1) as usize;
        let y = y.clamp(0, self.height as isize - 1) as usize;
        self.data[y * self.width + x]
    }

    /// Bilinear sample, clamped at the borders.
    fn sample(&self, x: f32, y: f32) -> f32 {
        let (fx, fy) = (x.floor(), y.floor());
        let (ax, ay) = (x - fx, y - fy);
        let (ix, iy) = (fx as isize, fy as isize);
        let top = self.at(ix, iy) * (1.0 - ax) + self.at(ix + 1, iy) * ax;
        let bottom = self.at(ix, iy + 1) * (1.0 - ax) + self.at(ix + 1, iy + 1) * ax;
        top * (1.0 - ay) + bottom * ay
    }

    /// Blurred by the binomial filter [1, 4, 6, 4, 1] / 16 across and down.
    fn blurred(&self) -> Gray {
        const TAPS: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
        let pass = |g: &Gray, dx: isize, dy: isize| {
            let mut data = Vec::with_capacity(g.data.len());
            for y in 0..g.height as isize {
                for x in 0..g.width as isize {
                    data.push(
                        (-2..=2)
                            .zip(TAPS)
                            .map(|(k, t)| t * g.at(x + k * dx, y + k * dy))
                            .sum(),
                    );
                }
            }
            Gray { data, ..*g }
        };
        pass(&pass(self, 1, 0), 0, 1)
    }

    /// Half the size, each pixel the mean of a 2 × 2 block.
    fn half(&self) -> Gray {
        let (width, height) = (self.width / 2, self.height / 2);
        let mut data = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                let (sx, sy) = (2 * x as isize, 2 * y as isize);
                data.push(
                    (self.at(sx, sy)
                        + self.at(sx + 1, sy)
                        + self.at(sx, sy + 1)
                        + self.at(sx + 1, sy + 1))
                        / 4.0,
                );
            }
        }
        Gray {
            width,
            height,
            data,
        }
    }
}

/// A dense flow field: where each pixel of the first image moved to in the second.
#[derive(Clone, Debug)]
pub struct Flow {
    pub width: usize,
    pub height: usize,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
}

impl Flow {
    fn zero(width: usize, height: usize) -> Flow {
        Flow {
            width,
            height,
            u: vec![0.0; width * height],
            v: vec![0.0; width * height],
        }
    }

    /// The flow at twice the size (and twice the displacement), bilinearly.
    fn upsampled(&self, width: usize, height: usize) -> Flow {
        let scale_x = self.width as f32 / width as f32;
        let scale_y = self.height as f32 / height as f32;
        let field = |d: &[f32]| Gray {
            width: self.width,
            height: self.height,
            data: d.to_vec(),
        };
        let (fu, fv) = (field(&self.u), field(&self.v));
        let mut out = Flow::zero(width, height);
        for y in 0..height {
            for x in 0..width {
                let sx = (x as f32 + 0.5) * scale_x - 0.5;
                let sy = (y as f32 + 0.5) * scale_y - 0.5;
                out.u[y * width + x] = fu.sample(sx, sy) / scale_x;
                out.v[y * width + x] = fv.sample(sx, sy) / scale_y;
            }
        }
        out
    }

    /// Mean length of the per-pixel difference of two flows of the same size.
    pub fn mean_difference(&self, other: &Flow) -> f64 {
        assert_eq!((self.width, self.height), (other.width, other.height));
        let sum: f64 = (0..self.u.len())
            .map(|i| {
                let (du, dv) = (self.u[i] - other.u[i], self.v[i] - other.v[i]);
                ((du * du + dv * dv) as f64).sqrt()
            })
            .sum();
        sum / self.u.len() as f64
    }
}

/// Horn-Schunck iterations refining `flow` from `a` to `b` at one level.
fn refine(a: &Gray, b: &Gray, flow: &mut Flow) {
    let (w, h) = (a.width, a.height);
    // b warped back by the flow so far; the iterations solve for the increment.
    let mut warped = Gray {
        width: w,
        height: h,
        data: vec![0.0; w * h],
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            warped.data[i] = b.sample(x as f32 + flow.u[i], y as f32 + flow.v[i]);
        }
    }
    let mut ix = vec![0.0; w * h];
    let mut iy = vec![0.0; w * h];
    let mut it = vec![0.0; w * h];
    for y in 0..h as isize {
        for x in 0..w as isize {
            let i = y as usize * w + x as usize;
            ix[i] =
                (a.at(x + 1, y) - a.at(x - 1, y) + warped.at(x + 1, y) - warped.at(x - 1, y)) / 4.0;
            iy[i] =
                (a.at(x, y + 1) - a.at(x, y - 1) + warped.at(x, y + 1) - warped.at(x, y - 1)) / 4.0;
            it[i] = warped.data[i] - a.data[i];
        }
    }
    let alpha2 = SMOOTHNESS * SMOOTHNESS;
    let mut du = Flow::zero(w, h);
    let mut next = Flow::zero(w, h);
    // The smoothness acts on the whole flow: the increment is smoothed together
    // with the flow it adds to.
    let base = flow.clone();
    for _ in 0..ITERATIONS {
        for y in 0..h as isize {
            for x in 0..w as isize {
                let i = y as usize * w + x as usize;
                let mean = |f: &[f32], g: &[f32]| {
                    let at = |dx: isize, dy: isize| {
                        let xx = (x + dx).clamp(0, w as isize - 1) as usize;
                        let yy = (y + dy).clamp(0, h as isize - 1) as usize;
                        let j = yy * w + xx;
                        f[j] + g[j]
                    };
                    (at(-1, 0) + at(1, 0) + at(0, -1) + at(0, 1)) / 4.0 - g[i]
                };
                let (mu, mv) = (mean(&du.u, &base.u), mean(&du.v, &base.v));
                let residual = ix[i] * mu + iy[i] * mv + it[i];
                let denom = alpha2 + ix[i] * ix[i] + iy[i] * iy[i];
                next.u[i] = mu - ix[i] * residual / denom;
                next.v[i] = mv - iy[i] * residual / denom;
            }
        }
        std::mem::swap(&mut du, &mut next);
    }
    for i in 0..w * h {
        flow.u[i] += du.u[i];
        flow.v[i] += du.v[i];
    }
}

/// The optical flow from `a` to `b` (the same size).
pub fn optical_flow(a: &Gray, b: &Gray) -> Flow {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let mut pyramid = vec![(a.blurred(), b.blurred())];
    while pyramid
        .last()
        .is_some_and(|(a, _)| a.width.min(a.height) / 2 >= COARSEST)
    {
        let (a, b) = pyramid.last().unwrap();
        pyramid.push((a.half(), b.half()));
    }
    let mut flow: Option<Flow> = None;
    for (a, b) in pyramid.iter().rev() {
        let mut f = match flow {
            Some(f) => f.upsampled(a.width, a.height),
            None => Flow::zero(a.width, a.height),
        };
        refine(a, b, &mut f);
        flow = Some(f);
    }
    flow.expect("a pyramid has a level")
}

/// TecoGAN's tOF for one pair of consecutive frames: the mean length of the
/// difference between the output's flow and the truth's, in pixels.
pub fn tof(output: (&Gray, &Gray), truth_flow: &Flow) -> f64 {
    optical_flow(output.0, output.1).mean_difference(truth_flow)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth texture, like skin and hair at a distance, moved by (dx, dy).
    fn texture(width: usize, height: usize, dx: f32, dy: f32) -> Gray {
        let data = (0..width * height)
            .map(|i| {
                let (x, y) = ((i % width) as f32 - dx, (i / width) as f32 - dy);
                0.5 + 0.2 * (x * 0.21).sin() * (y * 0.17).cos()
                    + 0.15 * ((x + 2.0 * y) * 0.07).sin()
                    + 0.1 * ((x - y) * 0.11).cos()
            })
            .collect();
        Gray {
            width,
            height,
            data,
        }
    }

    /// The median flow over the inner part of the image (borders have no match).
    fn median_inner(flow: &Flow) -> (f32, f32) {
        let mut u = Vec::new();
        let mut v = Vec::new();
        let m = flow.width / 8;
        for y in m..flow.height - m {
            for x in m..flow.width - m {
                u.push(flow.u[y * flow.width + x]);
                v.push(flow.v[y * flow.width + x]);
            }
        }
        u.sort_by(f32::total_cmp);
        v.sort_by(f32::total_cmp);
        (u[u.len() / 2], v[v.len() / 2])
    }

    #[test]
    fn finds_small_and_large_motions() {
        for (dx, dy) in [(0.7, -0.4), (3.0, 2.0), (-6.0, 4.5)] {
            let a = texture(128, 96, 0.0, 0.0);
            let b = texture(128, 96, dx, dy);
            let (u, v) = median_inner(&optical_flow(&a, &b));
            assert!(
                (u - dx).abs() < 0.15 * dx.abs().max(1.0)
                    && (v - dy).abs() < 0.15 * dy.abs().max(1.0),
                "moved ({dx}, {dy}), found ({u:.2}, {v:.2})"
            );
        }
    }

    #[test]
    fn tof_is_zero_for_the_truth_and_grows_with_wrong_motion() {
        let frames: Vec<Gray> = (0..3).map(|i| texture(96, 96, i as f32, 0.0)).collect();
        let truth = optical_flow(&frames[0], &frames[1]);
        assert!(tof((&frames[0], &frames[1]), &truth) < 1e-9);
        // Output that stood still while the truth moved by a pixel.
        let still = tof((&frames[0], &frames[0]), &truth);
        assert!(still > 0.6, "{still}");
        // Output that moved twice as far.
        let twice = tof((&frames[0], &frames[2]), &truth);
        assert!(twice > 0.6, "{twice}");
    }

    #[test]
    fn a_uniform_brightness_change_is_not_motion() {
        let a = texture(96, 96, 0.0, 0.0);
        let mut b = a.clone();
        for p in &mut b.data {
            *p *= 1.05;
        }
        let f = optical_flow(&a, &b);
        let (u, v) = median_inner(&f);
        assert!(u.abs() < 0.2 && v.abs() < 0.2, "({u}, {v})");
    }
}
