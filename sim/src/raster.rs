//! A z-buffer triangle rasteriser for the camera view and for shadow maps.
//!
//! The screen is cut into horizontal bands, one per task; a pixel belongs to
//! exactly one band and triangles are visited in mesh order, so the result is
//! the same for any number of threads.

use rayon::prelude::*;

use crate::math::{Mat3, Vec3};
use crate::mesh::Mesh;

/// A pinhole view: world-to-view rotation, centre of projection, intrinsics.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub rot: Mat3,
    pub origin: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: usize,
    pub height: usize,
}

impl View {
    /// The webcam: at the origin, looking along +z, with a vertical field of view in degrees.
    pub fn camera(width: usize, height: usize, vfov_deg: f32) -> View {
        let f = 0.5 * height as f32 / (0.5 * vfov_deg.to_radians()).tan();
        View {
            rot: Mat3::IDENTITY,
            origin: Vec3::ZERO,
            fx: f,
            fy: f,
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
            width,
            height,
        }
    }

    /// A square view from `origin` towards `target` with a field of view in degrees.
    pub fn look_at(origin: Vec3, target: Vec3, fov_deg: f32, size: usize) -> View {
        let fwd = (target - origin).normalized();
        let helper = if fwd.y.abs() < 0.9 {
            Vec3::new(0.0, 1.0, 0.0)
        } else {
            Vec3::new(1.0, 0.0, 0.0)
        };
        let right = helper.cross(fwd).normalized();
        let down = fwd.cross(right);
        let f = 0.5 * size as f32 / (0.5 * fov_deg.to_radians()).tan();
        View {
            rot: Mat3 {
                rows: [right, down, fwd],
            },
            origin,
            fx: f,
            fy: f,
            cx: 0.5 * size as f32,
            cy: 0.5 * size as f32,
            width: size,
            height: size,
        }
    }

    pub fn to_view(&self, p: Vec3) -> Vec3 {
        self.rot.mul_vec(p - self.origin)
    }

    /// Pixel coordinates (x right, y down; pixel centres at +0.5) and view depth.
    pub fn project(&self, p: Vec3) -> (f32, f32, f32) {
        let v = self.to_view(p);
        (
            self.fx * v.x / v.z + self.cx,
            self.fy * v.y / v.z + self.cy,
            v.z,
        )
    }

    /// Direction of the ray through pixel coordinates (x, y), in the world frame.
    pub fn ray(&self, x: f32, y: f32) -> Vec3 {
        let v = Vec3::new((x - self.cx) / self.fx, (y - self.cy) / self.fy, 1.0);
        // The rotation is orthonormal, so its transpose maps view to world.
        let r = &self.rot.rows;
        Vec3::new(
            r[0].x * v.x + r[1].x * v.y + r[2].x * v.z,
            r[0].y * v.x + r[1].y * v.y + r[2].y * v.z,
            r[0].z * v.x + r[1].z * v.y + r[2].z * v.z,
        )
        .normalized()
    }
}

/// What the camera sees at a pixel: the triangle and perspective-correct barycentrics.
#[derive(Clone, Copy, Debug)]
pub struct Fragment {
    pub depth: f32,
    pub triangle: u32,
    pub bary: [f32; 3],
}

pub const NO_TRIANGLE: u32 = u32::MAX;
const NEAR: f32 = 0.01;
const ROWS_PER_BAND: usize = 16;

struct Projected {
    x: f32,
    y: f32,
    inv_z: f32,
}

fn project_all(view: &View, mesh: &Mesh) -> Vec<Projected> {
    mesh.vertices
        .iter()
        .map(|v| {
            let (x, y, z) = view.project(v.pos);
            Projected {
                x,
                y,
                inv_z: 1.0 / z.max(NEAR),
            }
        })
        .collect()
}

/// Rasterises `mesh`; `visit(pixel, fragment)` is called for each covered pixel's
/// nearest fragment, in the band that owns the pixel.
fn rasterise<T: Send + Clone>(
    view: &View,
    mesh: &Mesh,
    empty: T,
    write: impl Fn(&mut T, Fragment) + Sync,
    depth_of: impl Fn(&T) -> f32 + Sync,
) -> Vec<T> {
    let (w, h) = (view.width, view.height);
    let proj = project_all(view, mesh);
    let bands = h.div_ceil(ROWS_PER_BAND);
    // Bin triangles by the bands their rows touch, keeping mesh order in each bin.
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|k| &proj[k as usize]);
        if a.inv_z >= 1.0 / NEAR || b.inv_z >= 1.0 / NEAR || c.inv_z >= 1.0 / NEAR {
            continue;
        }
        let min_y = a.y.min(b.y).min(c.y);
        let max_y = a.y.max(b.y).max(c.y);
        if max_y < 0.0 || min_y >= h as f32 {
            continue;
        }
        let b0 = (min_y.max(0.0) as usize) / ROWS_PER_BAND;
        let b1 = ((max_y.min(h as f32 - 1.0)) as usize) / ROWS_PER_BAND;
        for bin in &mut bins[b0..=b1] {
            bin.push(ti as u32);
        }
    }
    let mut buf = vec![empty; w * h];
    buf.par_chunks_mut(w * ROWS_PER_BAND)
        .zip(&bins)
        .enumerate()
        .for_each(|(band, (rows, bin))| {
            let y0 = band * ROWS_PER_BAND;
            let y1 = y0 + rows.len() / w;
            for &ti in bin {
                let [a, b, c] = mesh.triangles[ti as usize].map(|k| &proj[k as usize]);
                let min_y = a.y.min(b.y).min(c.y);
                let max_y = a.y.max(b.y).max(c.y);
                let py0 = ((min_y - 0.5).ceil().max(y0 as f32)) as isize;
                let py1 = ((max_y - 0.5).floor().min(y1 as f32 - 1.0)) as isize;
                if py0 > py1 {
                    continue;
                }
                let min_x = a.x.min(b.x).min(c.x);
                let max_x = a.x.max(b.x).max(c.x);
                let px0 = (min_x - 0.5).ceil().max(0.0) as isize;
                let px1 = (max_x - 0.5).floor().min(w as f32 - 1.0) as isize;
                if px0 > px1 {
                    continue;
                }
                let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
                if area.abs() < 1e-12 {
                    continue;
                }
                let inv_area = 1.0 / area;
                for py in py0..=py1 {
                    let sy = py as f32 + 0.5;
                    let row = (py as usize - y0) * w;
                    for px in px0..=px1 {
                        let sx = px as f32 + 0.5;
                        let l0 = ((b.x - sx) * (c.y - sy) - (b.y - sy) * (c.x - sx)) * inv_area;
                        let l1 = ((c.x - sx) * (a.y - sy) - (c.y - sy) * (a.x - sx)) * inv_area;
                        let l2 = 1.0 - l0 - l1;
                        if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                            continue;
                        }
                        let w0 = l0 * a.inv_z;
                        let w1 = l1 * b.inv_z;
                        let w2 = l2 * c.inv_z;
                        let inv_depth = w0 + w1 + w2;
                        let depth = 1.0 / inv_depth;
                        let slot = &mut rows[row + px as usize];
                        if depth < depth_of(slot) {
                            let frag = Fragment {
                                depth,
                                triangle: ti,
                                bary: [w0 * depth, w1 * depth, w2 * depth],
                            };
                            write(slot, frag);
                        }
                    }
                }
            }
        });
    buf
}

/// Nearest fragment per pixel, or a fragment with `NO_TRIANGLE`.
pub fn gbuffer(view: &View, mesh: &Mesh) -> Vec<Fragment> {
    let empty = Fragment {
        depth: f32::INFINITY,
        triangle: NO_TRIANGLE,
        bary: [0.0; 3],
    };
    rasterise(view, mesh, empty, |slot, f| *slot = f, |slot| slot.depth)
}

/// A depth map seen from a light, for shadow tests.
#[derive(Clone, Debug)]
pub struct ShadowMap {
    pub view: View,
    pub depth: Vec<f32>,
}

impl ShadowMap {
    pub fn render(view: View, mesh: &Mesh) -> ShadowMap {
        let depth = rasterise(
            &view,
            mesh,
            f32::INFINITY,
            |slot, f| *slot = f.depth,
            |slot| *slot,
        );
        ShadowMap { view, depth }
    }

    /// Fraction of the light that reaches `p` (0 shadowed, 1 lit), with bilinear
    /// filtering of the depth comparisons for soft, alias-free edges.
    pub fn visibility(&self, p: Vec3, bias: f32) -> f32 {
        let (x, y, z) = self.view.project(p);
        let (w, h) = (self.view.width, self.view.height);
        let fx = x - 0.5;
        let fy = y - 0.5;
        if !(fx >= 0.0 && fy >= 0.0 && fx < (w - 1) as f32 && fy < (h - 1) as f32) {
            return 1.0;
        }
        let (ix, iy) = (fx as usize, fy as usize);
        let (tx, ty) = (fx - ix as f32, fy - iy as f32);
        let lit = |xx: usize, yy: usize| (z - bias <= self.depth[yy * w + xx]) as u8 as f32;
        let top = lit(ix, iy) * (1.0 - tx) + lit(ix + 1, iy) * tx;
        let bottom = lit(ix, iy + 1) * (1.0 - tx) + lit(ix + 1, iy + 1) * tx;
        top * (1.0 - ty) + bottom * ty
    }
}
