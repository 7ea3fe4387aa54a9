//! Light transport and the webcam.
//!
//! For a pose, [`Renderer::prepare`] computes each pixel's geometry,
//! material, room light and per-shadow-group visibility: the [`Transport`].
//! Rendering a monitor light is then the sum over cells of
//! `transport(pixel, cell) × radiance(cell)`, evaluated for many lights at
//! once. The image is linear in the monitor's radiance:
//!
//! `image = ambient + Σ_cells transport_cell × radiance_cell`
//!
//! in linear light before the camera curve. [`Sensor`] then adds noise,
//! applies the sRGB curve and quantises to 8 bits.

use rayon::prelude::*;

use crate::material::{self, Look, Surface};
use crate::math::Vec3;
use crate::mesh::{self, Detail, HEAD_REST, Mesh, Template};
use crate::monitor::{CellLight, MonitorGeometry, RgbImage, linear_to_srgb};
use crate::raster::{self, NO_TRIANGLE, ShadowMap, View};
use crate::rng::{gaussian_pair, hash};
use crate::subject::{State, Subject};

/// Vertical field of view of the webcam, degrees.
pub const VERTICAL_FOV_DEG: f32 = 40.0;

/// Accumulator lanes of the dot products.
const LANES: usize = 16;

/// Fixed set-up of the desk: camera, monitor, room and exposure.
#[derive(Clone, Debug)]
pub struct Scene {
    pub subject: Subject,
    pub monitor: MonitorGeometry,
    pub camera: View,
    /// Distance of the back wall from the camera, metres.
    pub wall_z: f32,
    /// Resolution of each shadow group's depth map.
    pub shadow_map_size: usize,
    /// Cast shadows on (off only to show in tests that they matter).
    pub shadows: bool,
}

impl Scene {
    /// The default desk with a camera of `width`×`height` pixels and a 40° vertical
    /// field of view: head and shoulders fill the height of the frame.
    pub fn new(subject: Subject, width: usize, height: usize) -> Scene {
        Scene {
            subject,
            monitor: MonitorGeometry::default(),
            camera: View::camera(width, height, VERTICAL_FOV_DEG),
            wall_z: 1.45,
            shadow_map_size: 256,
            shadows: true,
        }
    }
}

/// A linear, sensor-referred image: 1.0 saturates the sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<Vec3>,
}

impl LinearImage {
    pub fn is_finite(&self) -> bool {
        self.rgb.iter().all(|v| v.is_finite())
    }
}

/// Monitor cells as structure-of-arrays, ordered by shadow group so that each
/// group is one contiguous run of `per_group` cells sharing one visibility.
#[derive(Clone, Debug)]
struct CellTable {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    /// The way each cell faces, scaled by its area over the mean
    /// (`MonitorGeometry::cell_facing`).
    facing_x: Vec<f32>,
    facing_y: Vec<f32>,
    facing_z: Vec<f32>,
    /// Table slot of cell (row, col), row-major.
    slot: Vec<usize>,
    per_group: usize,
}

impl CellTable {
    fn new(m: &MonitorGeometry) -> CellTable {
        let n = m.rows * m.cols;
        let per_group = n / m.groups();
        let mut t = CellTable {
            x: vec![0.0; n],
            y: vec![0.0; n],
            z: vec![0.0; n],
            facing_x: vec![0.0; n],
            facing_y: vec![0.0; n],
            facing_z: vec![0.0; n],
            slot: vec![0; n],
            per_group,
        };
        let mut filled = vec![0usize; m.groups()];
        for r in 0..m.rows {
            for c in 0..m.cols {
                let g = m.group_of(r, c);
                let k = g * per_group + filled[g];
                filled[g] += 1;
                let p = m.cell_centre(r, c);
                t.x[k] = p.x;
                t.y[k] = p.y;
                t.z[k] = p.z;
                let f = m.cell_facing(r, c);
                (t.facing_x[k], t.facing_y[k], t.facing_z[k]) = (f.x, f.y, f.z);
                t.slot[r * m.cols + c] = k;
            }
        }
        t
    }

    fn len(&self) -> usize {
        self.x.len()
    }
}

/// A pixel that shows the person, with what its shading needs.
#[derive(Clone, Copy, Debug)]
struct SubjectPixel {
    pos: Vec3,
    normal: Vec3,
    /// Unit vector from the surface to the camera.
    view: Vec3,
    surface: Surface,
}

/// Marks pixels of [`Transport::subject_at`] that show the wall.
const WALL: u32 = u32::MAX;

/// Monitor light on the back wall, sampled every `step` pixels: per sample and
/// shadow group, the transport weight (geometry times visibility). The wall is
/// far from the screen and its shadows are soft, so samples are interpolated.
#[derive(Clone, Debug)]
struct WallGrid {
    step: usize,
    cols: usize,
    weights: Vec<f32>,
}

/// Everything about one pose that does not depend on the monitor's content.
#[derive(Clone, Debug)]
pub struct Transport {
    pub width: usize,
    pub height: usize,
    /// Per pixel: index into `subject`, or `WALL`.
    subject_at: Vec<u32>,
    subject: Vec<SubjectPixel>,
    /// Per subject pixel, the visible fraction of each shadow group.
    subject_visibility: Vec<f32>,
    /// Per pixel: diffuse albedo and room light.
    albedo: Vec<Vec3>,
    ambient: Vec<Vec3>,
    wall: WallGrid,
    groups: usize,
}

impl Transport {
    /// Which pixels show the person.
    pub fn subject_mask(&self) -> Vec<bool> {
        self.subject_at.iter().map(|&i| i != WALL).collect()
    }
}

/// Renders poses of one subject in one scene.
#[derive(Clone, Debug)]
pub struct Renderer {
    pub scene: Scene,
    camera_mesh: Template,
    shadow_mesh: Template,
    cells: CellTable,
    /// Sensor gain: linear radiance to sensor units.
    exposure: f32,
    /// Irradiance on the face from a full-white monitor, divided by π.
    white_irradiance: f32,
    cell_area_over_pi: f32,
}

/// Field of view of the shadow maps, degrees: the whole head and shoulders.
const SHADOW_FOV_DEG: f32 = 64.0;

/// One row of the precompute: albedo, ambient, and the subject pixels (with their
/// column) and their visibility.
type PreparedRow = (Vec<Vec3>, Vec<Vec3>, Vec<(usize, SubjectPixel)>, Vec<f32>);

/// Pixel spacing of the wall's transport samples.
const WALL_STEP: usize = 4;

impl Renderer {
    pub fn new(scene: Scene) -> Result<Renderer, String> {
        scene.monitor.check()?;
        let cells = CellTable::new(&scene.monitor);
        let cell_area_over_pi = scene.monitor.cell_area() / std::f32::consts::PI;
        // Reference: a frontal patch at the rest position of the face.
        let face = HEAD_REST - Vec3::new(0.0, 0.0, 0.09);
        let mut e = 0.0;
        for k in 0..cells.len() {
            let d = Vec3::new(cells.x[k], cells.y[k], cells.z[k]) - face;
            let facing = Vec3::new(cells.facing_x[k], cells.facing_y[k], cells.facing_z[k]);
            let r = d.dot(d).sqrt();
            let cos_face = (-d.z).max(0.0) / r;
            let cos_cell = (-facing.dot(d)).max(0.0) / r;
            e += cos_face * cos_cell / (r * r);
        }
        let white_irradiance = e * cell_area_over_pi;
        // Fixed exposure: skin of albedo 0.5 facing a white screen reaches about 0.42.
        let exposure = 0.85 / white_irradiance;
        Ok(Renderer {
            camera_mesh: Template::new(&scene.subject, Detail::CAMERA),
            shadow_mesh: Template::new(&scene.subject, Detail::SHADOW),
            scene,
            cells,
            exposure,
            white_irradiance,
            cell_area_over_pi,
        })
    }

    pub fn width(&self) -> usize {
        self.scene.camera.width
    }

    pub fn height(&self) -> usize {
        self.scene.camera.height
    }

    /// The per-pose precompute: geometry, materials, room light and shadow visibility.
    pub fn prepare(&self, look: &Look, state: &State) -> Transport {
        let scene = &self.scene;
        let cam = &scene.camera;
        let subject = &scene.subject;
        let fine = self.camera_mesh.build(subject, state);
        let frags = raster::gbuffer(cam, &fine);
        let maps = self.shadow_maps(state);
        let groups = scene.monitor.groups();
        let amb = look.ambient;
        let amb_scale = amb.tint * (amb.ratio * self.white_irradiance * self.exposure);
        let (w, h) = (cam.width, cam.height);

        let rows: Vec<PreparedRow> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut albedo = Vec::with_capacity(w);
                let mut ambient = Vec::with_capacity(w);
                let mut people = Vec::new();
                let mut vis = Vec::new();
                for x in 0..w {
                    let f = frags[y * w + x];
                    let (surface, normal) = if f.triangle != NO_TRIANGLE {
                        let px = subject_pixel(&fine, subject, look, f);
                        // Offset along the normal so surfaces do not shadow themselves.
                        let probe = px.pos + px.normal * 0.0015;
                        vis.extend(maps.iter().map(|m| m.visibility(probe, 0.002)));
                        if maps.is_empty() {
                            vis.extend(std::iter::repeat_n(1.0, groups));
                        }
                        people.push((x, px));
                        (px.surface, px.normal)
                    } else {
                        let pos = self.wall_point(x as f32 + 0.5, y as f32 + 0.5);
                        (material::wall(pos.x, pos.y), WALL_NORMAL)
                    };
                    albedo.push(surface.albedo);
                    ambient.push(surface.albedo.scale(amb_scale) * amb.shape(normal));
                }
                (albedo, ambient, people, vis)
            })
            .collect();

        let mut t = Transport {
            width: w,
            height: h,
            subject_at: vec![WALL; w * h],
            subject: Vec::new(),
            subject_visibility: Vec::new(),
            albedo: Vec::with_capacity(w * h),
            ambient: Vec::with_capacity(w * h),
            wall: self.wall_grid(&maps),
            groups,
        };
        for (y, (albedo, ambient, people, vis)) in rows.into_iter().enumerate() {
            t.albedo.extend(albedo);
            t.ambient.extend(ambient);
            for (x, px) in people {
                t.subject_at[y * w + x] = t.subject.len() as u32;
                t.subject.push(px);
            }
            t.subject_visibility.extend(vis);
        }
        t
    }

    /// Where the camera ray through pixel coordinates (x, y) meets the back wall.
    fn wall_point(&self, x: f32, y: f32) -> Vec3 {
        let ray = self.scene.camera.ray(x, y);
        ray * (self.scene.wall_z / ray.z)
    }

    fn wall_grid(&self, maps: &[ShadowMap]) -> WallGrid {
        let m = &self.scene.monitor;
        let cam = &self.scene.camera;
        let cols = (cam.width - 1) / WALL_STEP + 2;
        let rows = (cam.height - 1) / WALL_STEP + 2;
        let group_area_over_pi = self.cell_area_over_pi * self.cells.per_group as f32;
        let centres: Vec<(Vec3, Vec3)> = (0..m.groups())
            .map(|g| (m.group_centre(g), m.group_facing(g)))
            .collect();
        let weights = (0..rows * cols)
            .into_par_iter()
            .flat_map_iter(|s| {
                let (i, j) = (s % cols, s / cols);
                let p = self.wall_point((i * WALL_STEP) as f32 + 0.5, (j * WALL_STEP) as f32 + 0.5);
                let probe = p + WALL_NORMAL * 0.002;
                centres.iter().enumerate().map(move |(g, (c, facing))| {
                    let d = *c - p;
                    let r2 = d.dot(d);
                    let cos_p = WALL_NORMAL.dot(d).max(0.0);
                    let cos_m = (-facing.dot(d)).max(0.0);
                    let vis = maps.get(g).map_or(1.0, |map| map.visibility(probe, 0.01));
                    cos_p * cos_m / (r2 * r2) * group_area_over_pi * vis
                })
            })
            .collect();
        WallGrid {
            step: WALL_STEP,
            cols,
            weights,
        }
    }

    fn shadow_maps(&self, state: &State) -> Vec<ShadowMap> {
        if !self.scene.shadows || !state.pose.present {
            return Vec::new();
        }
        let coarse = self.shadow_mesh.build(&self.scene.subject, state);
        // Aimed at the middle of head and shoulders, wide enough for all of them:
        // every occluder is in view, so points outside the map are lit.
        let target =
            HEAD_REST + state.pose.body + state.pose.translation + Vec3::new(0.0, 0.13, 0.0);
        let m = &self.scene.monitor;
        (0..m.groups())
            .into_par_iter()
            .map(|g| {
                let view = View::look_at(
                    m.group_centre(g),
                    target,
                    SHADOW_FOV_DEG,
                    self.scene.shadow_map_size,
                );
                ShadowMap::render(view, &coarse)
            })
            .collect()
    }

    /// The monitor's linear radiance per cell in sensor units, channel-major, in table order.
    fn light_channels(&self, light: &CellLight) -> [Vec<f32>; 3] {
        let m = &self.scene.monitor;
        assert_eq!(
            (light.rows, light.cols),
            (m.rows, m.cols),
            "a monitor light must have the monitor's cell grid"
        );
        let n = self.cells.len();
        let mut ch = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        for (v, &k) in light.rgb.iter().zip(&self.cells.slot) {
            ch[0][k] = v.x * self.exposure;
            ch[1][k] = v.y * self.exposure;
            ch[2][k] = v.z * self.exposure;
        }
        ch
    }

    /// Room light only: the image under a black monitor.
    pub fn ambient(&self, t: &Transport) -> LinearImage {
        LinearImage {
            width: t.width,
            height: t.height,
            rgb: t.ambient.clone(),
        }
    }

    /// Renders the pose under each monitor light; batching lights shares the per-cell work.
    pub fn render(&self, t: &Transport, lights: &[&CellLight]) -> Vec<LinearImage> {
        let channels: Vec<[Vec<f32>; 3]> = lights.iter().map(|l| self.light_channels(l)).collect();
        let n = lights.len();
        let (w, h) = (t.width, t.height);
        let wall = self.wall_irradiance(t, &channels);
        // Pixel-major: light m of pixel i at i * n + m.
        let mut interleaved = vec![Vec3::ZERO; w * h * n];
        interleaved
            .par_chunks_mut(w * n)
            .enumerate()
            .for_each(|(y, row)| {
                let mut scratch = Scratch::new(self.cells.len(), n);
                for x in 0..w {
                    let i = y * w + x;
                    let out = &mut row[x * n..(x + 1) * n];
                    match t.subject_at[i] {
                        WALL => {
                            let fx = x as f32 / t.wall.step as f32;
                            let fy = y as f32 / t.wall.step as f32;
                            let (ix, iy) = (fx as usize, fy as usize);
                            let (tx, ty) = (fx - ix as f32, fy - iy as f32);
                            let at = |i: usize, j: usize| (j * t.wall.cols + i) * n;
                            let (a, b) = (at(ix, iy), at(ix + 1, iy));
                            let (c, d) = (at(ix, iy + 1), at(ix + 1, iy + 1));
                            for (m, o) in out.iter_mut().enumerate() {
                                let top = wall[a + m] * (1.0 - tx) + wall[b + m] * tx;
                                let bottom = wall[c + m] * (1.0 - tx) + wall[d + m] * tx;
                                *o = t.ambient[i]
                                    + t.albedo[i].scale(top * (1.0 - ty) + bottom * ty);
                            }
                        }
                        k => {
                            let k = k as usize;
                            let p = &t.subject[k];
                            let vis = &t.subject_visibility[k * t.groups..(k + 1) * t.groups];
                            subject_sums_dispatch(
                                p,
                                vis,
                                &self.cells,
                                self.cell_area_over_pi,
                                &channels,
                                &mut scratch,
                            );
                            for (o, (d, s)) in out.iter_mut().zip(&scratch.sums) {
                                *o = t.ambient[i]
                                    + p.surface.albedo.scale(*d)
                                    + *s * p.surface.specular;
                            }
                        }
                    }
                }
            });
        (0..n)
            .map(|m| LinearImage {
                width: w,
                height: h,
                rgb: interleaved.iter().skip(m).step_by(n).copied().collect(),
            })
            .collect()
    }

    /// Irradiance over π at each wall sample for each light, sample-major.
    fn wall_irradiance(&self, t: &Transport, channels: &[[Vec<f32>; 3]]) -> Vec<Vec3> {
        let per = self.cells.per_group;
        // Each shadow group of the wall acts as one area light of its cells' mean radiance.
        let group_means: Vec<Vec<Vec3>> = channels
            .iter()
            .map(|ch| {
                let mean = |c: &Vec<f32>| {
                    c.chunks_exact(per)
                        .map(|g| g.iter().sum::<f32>() / per as f32)
                        .collect()
                };
                let [r, g, b]: [Vec<f32>; 3] = [mean(&ch[0]), mean(&ch[1]), mean(&ch[2])];
                (0..r.len()).map(|i| Vec3::new(r[i], g[i], b[i])).collect()
            })
            .collect();
        t.wall
            .weights
            .chunks_exact(t.groups)
            .flat_map(|ws| {
                group_means.iter().map(move |gm| {
                    ws.iter()
                        .zip(gm)
                        .fold(Vec3::ZERO, |acc, (w, l)| acc + *l * *w)
                })
            })
            .collect()
    }
}

/// The back wall faces the camera.
const WALL_NORMAL: Vec3 = Vec3::new(0.0, 0.0, -1.0);

/// Per-thread working memory of [`Renderer::render`].
struct Scratch {
    diffuse: Vec<f32>,
    specular: Vec<f32>,
    sums: Vec<(Vec3, Vec3)>,
}

impl Scratch {
    fn new(cells: usize, lights: usize) -> Scratch {
        Scratch {
            diffuse: vec![0.0; cells],
            specular: vec![0.0; cells],
            sums: vec![(Vec3::ZERO, Vec3::ZERO); lights],
        }
    }
}

fn subject_pixel(fine: &Mesh, subject: &Subject, look: &Look, f: raster::Fragment) -> SubjectPixel {
    let tri = fine.triangles[f.triangle as usize];
    let part = fine.triangle_part[f.triangle as usize];
    let [a, b, c] = tri.map(|k| &fine.vertices[k as usize]);
    let [w0, w1, w2] = f.bary;
    let pos = a.pos * w0 + b.pos * w1 + c.pos * w2;
    let mut normal = (a.normal * w0 + b.normal * w1 + c.normal * w2).normalized();
    let view = (-pos).normalized();
    // Thin parts (ears) are seen from both sides.
    if normal.dot(view) < 0.0 && part == mesh::Part::Ear {
        normal = -normal;
    }
    let uv = [
        a.uv[0] * w0 + b.uv[0] * w1 + c.uv[0] * w2,
        a.uv[1] * w0 + b.uv[1] * w1 + c.uv[1] * w2,
    ];
    SubjectPixel {
        pos,
        normal,
        view,
        surface: material::surface(subject, look, part, uv),
    }
}

/// Runs [`subject_sums`] with the widest vector instructions the CPU has.
/// Only the vector width changes, never the arithmetic, so every path gives
/// the same bits.
fn subject_sums_dispatch(
    p: &SubjectPixel,
    vis: &[f32],
    cells: &CellTable,
    area_over_pi: f32,
    lights: &[[Vec<f32>; 3]],
    s: &mut Scratch,
) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f")]
        fn avx512(
            p: &SubjectPixel,
            v: &[f32],
            c: &CellTable,
            a: f32,
            l: &[[Vec<f32>; 3]],
            s: &mut Scratch,
        ) {
            subject_sums(p, v, c, a, l, s)
        }
        #[target_feature(enable = "avx2")]
        fn avx2(
            p: &SubjectPixel,
            v: &[f32],
            c: &CellTable,
            a: f32,
            l: &[[Vec<f32>; 3]],
            s: &mut Scratch,
        ) {
            subject_sums(p, v, c, a, l, s)
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports the feature the function was compiled for.
            return unsafe { avx512(p, vis, cells, area_over_pi, lights, s) };
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: as above.
            return unsafe { avx2(p, vis, cells, area_over_pi, lights, s) };
        }
    }
    subject_sums(p, vis, cells, area_over_pi, lights, s)
}

/// Diffuse and specular sums of a subject pixel for each light, into `s.sums`.
///
/// First the per-cell transport weights, then their dot products with each
/// light. Written as straight loops over equal-length slices so they
/// vectorise; the arithmetic is plain IEEE (no fused operations), so results
/// do not depend on which instructions the compiler picks.
#[inline(always)]
fn subject_sums(
    p: &SubjectPixel,
    vis: &[f32],
    cells: &CellTable,
    area_over_pi: f32,
    lights: &[[Vec<f32>; 3]],
    s: &mut Scratch,
) {
    let (px, py, pz) = (p.pos.x, p.pos.y, p.pos.z);
    let (nx, ny, nz) = (p.normal.x, p.normal.y, p.normal.z);
    let (vx, vy, vz) = (p.view.x, p.view.y, p.view.z);
    let nv = p.normal.dot(p.view);
    let per = cells.per_group;
    let runs = cells
        .x
        .chunks_exact(per)
        .zip(cells.y.chunks_exact(per))
        .zip(cells.z.chunks_exact(per))
        .zip(cells.facing_x.chunks_exact(per))
        .zip(
            cells
                .facing_y
                .chunks_exact(per)
                .zip(cells.facing_z.chunks_exact(per)),
        )
        .zip(
            s.diffuse
                .chunks_exact_mut(per)
                .zip(s.specular.chunks_exact_mut(per)),
        )
        .zip(vis);
    for ((((((xs, ys), zs), fxs), (fys, fzs)), (diff, spec)), &v) in runs {
        let scale = area_over_pi * v;
        for k in 0..per {
            let dx = xs[k] - px;
            let dy = ys[k] - py;
            let dz = zs[k] - pz;
            let r2 = dx * dx + dy * dy + dz * dz;
            let inv_r = 1.0 / r2.sqrt();
            let ndot = (nx * dx + ny * dy + nz * dz).max(0.0);
            // The cosine at the cell is −(facing · d) / r; the facing carries the
            // cell's area. The screen's cells face +z, which leaves −dz.
            let mdot = (-(fxs[k] * dx + fys[k] * dy + fzs[k] * dz)).max(0.0);
            let inv_r2 = inv_r * inv_r;
            diff[k] = ndot * mdot * inv_r2 * inv_r2 * scale;
            // Blinn–Phong: (n·h)² with h the half vector of the light direction d/r
            // and the view, kept squared to save a square root.
            let dv = dx * vx + dy * vy + dz * vz;
            let n_sum = (ndot * inv_r + nv).max(0.0);
            let nh2 = n_sum * n_sum / (2.0 + 2.0 * dv * inv_r).max(1e-12);
            spec[k] = nh2.min(1.0);
        }
    }
    // (n·h)^(2^s) from (n·h)²: s − 1 more squarings.
    for _ in 1..p.surface.shine_log2 {
        for v in s.specular.iter_mut() {
            *v *= *v;
        }
    }
    let norm = ((1u32 << p.surface.shine_log2) as f32 + 8.0) / 8.0;
    for (sv, g) in s.specular.iter_mut().zip(&s.diffuse) {
        *sv *= g * norm;
    }
    for (sum, l) in s.sums.iter_mut().zip(lights) {
        let d = Vec3::new(
            dot(&s.diffuse, &l[0]),
            dot(&s.diffuse, &l[1]),
            dot(&s.diffuse, &l[2]),
        );
        let sp = Vec3::new(
            dot(&s.specular, &l[0]),
            dot(&s.specular, &l[1]),
            dot(&s.specular, &l[2]),
        );
        *sum = (d, sp);
    }
}

/// Dot product in fixed lanes: vectorises, and sums in the same order everywhere.
#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; LANES];
    let (ca, ra) = a.as_chunks::<LANES>();
    let (cb, rb) = b.as_chunks::<LANES>();
    for (x, y) in ca.iter().zip(cb) {
        for i in 0..LANES {
            acc[i] += x[i] * y[i];
        }
    }
    let tail: f32 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    acc.iter().sum::<f32>() + tail
}

/// A fixed-exposure webcam: shot and read noise, sRGB response, 8-bit output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    /// Standard deviation of read noise, in sensor units.
    pub read_noise: f32,
    /// Shot-noise variance per unit of signal.
    pub shot_noise: f32,
}

impl Default for Sensor {
    fn default() -> Self {
        Sensor {
            read_noise: 0.004,
            shot_noise: 0.0005,
        }
    }
}

impl Sensor {
    /// A webcam frame: noise drawn from (`seed`, `frame`), so the same inputs give the same bytes.
    pub fn capture(&self, img: &LinearImage, seed: u64, frame: u64) -> RgbImage {
        self.encode(img, Some((seed, frame)))
    }

    /// The noiseless frame: exact ground truth.
    pub fn clean(&self, img: &LinearImage) -> RgbImage {
        self.encode(img, None)
    }

    fn encode(&self, img: &LinearImage, noise: Option<(u64, u64)>) -> RgbImage {
        let mut out = RgbImage::new(img.width, img.height);
        out.data
            .par_chunks_mut(img.width * 3)
            .enumerate()
            .for_each(|(y, row)| {
                for x in 0..img.width {
                    let i = y * img.width + x;
                    let v = img.rgb[i];
                    let mut c = [v.x, v.y, v.z];
                    if let Some((seed, frame)) = noise {
                        let (n0, n1) = gaussian_pair(hash(seed, &[frame, i as u64, 0]));
                        let (n2, _) = gaussian_pair(hash(seed, &[frame, i as u64, 1]));
                        for (ch, n) in c.iter_mut().zip([n0, n1, n2]) {
                            let sigma = (self.read_noise * self.read_noise
                                + self.shot_noise * ch.max(0.0))
                            .sqrt();
                            *ch += sigma * n;
                        }
                    }
                    for k in 0..3 {
                        row[x * 3 + k] = (linear_to_srgb(c[k]) * 255.0).round() as u8;
                    }
                }
            });
        out
    }
}
