//! The monitor as a light source: geometry, cells and their radiance.
//!
//! A monitor frame is an sRGB image as a screen capture would record it.
//! Its light is the frame decoded to linear light and box-averaged into a
//! grid of cells; row 0 is the top of the screen and column 0 its left edge
//! as the user sees it. Each cell is an area light.
//!
//! The same grid lights the person from one of two layouts ([`Layout`]): the
//! desk's flat screen, which spans about 53 degrees, or the dome the light
//! code stands for, 180 degrees wide and 90 high round the head (the field an
//! environment becomes a target light over, `target-fov`), where a cell at the
//! grid's edge is a light from the side.

use crate::math::Vec3;
use crate::mesh::HEAD_REST;

/// An 8-bit sRGB image, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u8>,
}

impl RgbImage {
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            data: vec![0; width * height * 3],
        }
    }

    pub fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = (y * self.width + x) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }
}

/// sRGB-encoded value in [0, 1] to linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light in [0, 1] to sRGB-encoded value.
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Decoding table for 8-bit sRGB.
pub fn srgb8_to_linear_table() -> [f32; 256] {
    std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0))
}

/// Radiance of each monitor cell in linear light, 1.0 being full white.
#[derive(Clone, Debug, PartialEq)]
pub struct CellLight {
    pub rows: usize,
    pub cols: usize,
    /// Row-major, top row first, screen-left column first.
    pub rgb: Vec<Vec3>,
}

impl CellLight {
    pub fn uniform(rows: usize, cols: usize, rgb: Vec3) -> Self {
        Self {
            rows,
            cols,
            rgb: vec![rgb; rows * cols],
        }
    }

    /// Box average of a frame in linear light. The frame size must be a
    /// multiple of the grid, as for every frame the simulator shows.
    pub fn from_frame(frame: &RgbImage, rows: usize, cols: usize) -> Self {
        assert!(
            frame.width.is_multiple_of(cols) && frame.height.is_multiple_of(rows),
            "monitor frame {}x{} is not a multiple of the {cols}x{rows} cell grid",
            frame.width,
            frame.height
        );
        let lut = srgb8_to_linear_table();
        let (bw, bh) = (frame.width / cols, frame.height / rows);
        let norm = 1.0 / (bw * bh) as f32;
        let mut rgb = Vec::with_capacity(rows * cols);
        for r in 0..rows {
            for c in 0..cols {
                let mut sum = Vec3::ZERO;
                for y in r * bh..(r + 1) * bh {
                    for x in c * bw..(c + 1) * bw {
                        let [pr, pg, pb] = frame.pixel(x, y);
                        sum += Vec3::new(lut[pr as usize], lut[pg as usize], lut[pb as usize]);
                    }
                }
                rgb.push(sum * norm);
            }
        }
        Self { rows, cols, rgb }
    }

    pub fn add(&self, o: &CellLight) -> CellLight {
        CellLight {
            rows: self.rows,
            cols: self.cols,
            rgb: self.rgb.iter().zip(&o.rgb).map(|(a, b)| *a + *b).collect(),
        }
    }

    pub fn mean(&self) -> Vec3 {
        let n = self.rgb.len() as f32;
        self.rgb.iter().fold(Vec3::ZERO, |s, v| s + *v) * (1.0 / n)
    }
}

/// Where the monitor is and how it is cut into cells.
#[derive(Clone, Debug, PartialEq)]
pub struct MonitorGeometry {
    /// Width and height of the screen in metres.
    pub width_m: f32,
    pub height_m: f32,
    /// The screen's top edge, in metres below the camera.
    pub top_y: f32,
    /// Distance of the screen plane from the camera along the view axis (usually 0).
    pub z: f32,
    pub rows: usize,
    pub cols: usize,
    /// Cells are grouped for shadow tests: each group shares one shadow map.
    pub group_rows: usize,
    pub group_cols: usize,
    /// Where the cells are: on the screen, or on the dome.
    pub layout: Layout,
}

/// Where a monitor light's cells are round the person.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Layout {
    /// The desk: the flat screen of [`MonitorGeometry`]'s size, facing the user.
    Screen,
    /// The light stage the light code stands for: the cells on a sphere of
    /// `radius_m` round the head's rest position, column 0 at 90 degrees to the
    /// user's left and the last column at 90 degrees to the right, row 0 at 45
    /// degrees up and the last row at 45 degrees down, each facing the head.
    Dome { radius_m: f32 },
}

/// Horizontal and vertical field of the dome, degrees: `target-fov`'s default,
/// and half of it, as the element maps an environment onto the light grid.
pub const DOME_FIELD_DEG: (f32, f32) = (180.0, 90.0);

impl Default for MonitorGeometry {
    fn default() -> Self {
        // A 27" 16:9 screen with the webcam on its top edge.
        MonitorGeometry {
            width_m: 0.60,
            height_m: 0.3375,
            top_y: 0.012,
            z: 0.0,
            rows: 16,
            cols: 32,
            group_rows: 4,
            group_cols: 8,
            layout: Layout::Screen,
        }
    }
}

impl MonitorGeometry {
    /// The light stage the light code stands for ([`Layout::Dome`]), a metre
    /// round the head, with the desk's grid and shadow groups.
    pub fn dome() -> MonitorGeometry {
        MonitorGeometry {
            layout: Layout::Dome { radius_m: 1.0 },
            ..MonitorGeometry::default()
        }
    }

    /// Longitude (to the user's left, +) and latitude (up, +) of a point of the
    /// dome at grid coordinates `(row, col)` (cell units, 0 at the top-left corner).
    fn dome_angles(&self, row: f32, col: f32) -> (f32, f32) {
        let (wide, high) = DOME_FIELD_DEG;
        let lon = (0.5 - col / self.cols as f32) * wide;
        let lat = (0.5 - row / self.rows as f32) * high;
        (lon.to_radians(), lat.to_radians())
    }

    /// Unit vector from the head towards the dome at `(lon, lat)`, in the camera
    /// frame (x to image right, which is the user's left; y down; z away from
    /// the camera).
    fn dome_direction((lon, lat): (f32, f32)) -> Vec3 {
        Vec3::new(lon.sin() * lat.cos(), -lat.sin(), -lon.cos() * lat.cos())
    }

    /// Centre of cell (row, col) in the camera frame. The screen faces the
    /// user, so its left column (as the user sees it) is at image right, +x.
    pub fn cell_centre(&self, row: usize, col: usize) -> Vec3 {
        match self.layout {
            Layout::Screen => {
                let cw = self.width_m / self.cols as f32;
                let ch = self.height_m / self.rows as f32;
                Vec3::new(
                    0.5 * self.width_m - (col as f32 + 0.5) * cw,
                    self.top_y + (row as f32 + 0.5) * ch,
                    self.z,
                )
            }
            Layout::Dome { radius_m } => {
                let angles = self.dome_angles(row as f32 + 0.5, col as f32 + 0.5);
                HEAD_REST + Self::dome_direction(angles) * radius_m
            }
        }
    }

    /// Mean area of a cell, square metres.
    pub fn cell_area(&self) -> f32 {
        match self.layout {
            Layout::Screen => self.width_m * self.height_m / (self.rows * self.cols) as f32,
            Layout::Dome { .. } => {
                let total: f32 = (0..self.rows).map(|r| self.dome_cell_area(r)).sum();
                total * self.cols as f32 / (self.rows * self.cols) as f32
            }
        }
    }

    /// Area of a dome cell in `row`: the band of the sphere between its
    /// latitudes, cut into the grid's columns.
    fn dome_cell_area(&self, row: usize) -> f32 {
        let Layout::Dome { radius_m } = self.layout else {
            return self.cell_area();
        };
        let (_, top) = self.dome_angles(row as f32, 0.0);
        let (_, bottom) = self.dome_angles(row as f32 + 1.0, 0.0);
        let band = radius_m * radius_m * (top.sin() - bottom.sin());
        band * DOME_FIELD_DEG.0.to_radians() / self.cols as f32
    }

    /// The way cell (row, col) faces, towards the person, scaled by its area
    /// over the mean cell area: the screen's cells are all `(0, 0, 1)`; the
    /// dome's face the head and are smaller towards its top and bottom.
    pub fn cell_facing(&self, row: usize, col: usize) -> Vec3 {
        match self.layout {
            Layout::Screen => Vec3::new(0.0, 0.0, 1.0),
            Layout::Dome { .. } => {
                let angles = self.dome_angles(row as f32 + 0.5, col as f32 + 0.5);
                let inward = -Self::dome_direction(angles);
                inward * (self.dome_cell_area(row) / self.cell_area())
            }
        }
    }

    /// Shadow group of a cell.
    pub fn group_of(&self, row: usize, col: usize) -> usize {
        let gr = row * self.group_rows / self.rows;
        let gc = col * self.group_cols / self.cols;
        gr * self.group_cols + gc
    }

    pub fn groups(&self) -> usize {
        self.group_rows * self.group_cols
    }

    /// Centre of a shadow group.
    pub fn group_centre(&self, group: usize) -> Vec3 {
        let (gr, gc) = (group / self.group_cols, group % self.group_cols);
        match self.layout {
            Layout::Screen => {
                let gw = self.width_m / self.group_cols as f32;
                let gh = self.height_m / self.group_rows as f32;
                Vec3::new(
                    0.5 * self.width_m - (gc as f32 + 0.5) * gw,
                    self.top_y + (gr as f32 + 0.5) * gh,
                    self.z,
                )
            }
            Layout::Dome { radius_m } => {
                let (rows, cols) = (self.rows / self.group_rows, self.cols / self.group_cols);
                let angles = self.dome_angles(
                    (gr as f32 + 0.5) * rows as f32,
                    (gc as f32 + 0.5) * cols as f32,
                );
                HEAD_REST + Self::dome_direction(angles) * radius_m
            }
        }
    }

    /// The mean of a shadow group's cells' [`MonitorGeometry::cell_facing`].
    pub fn group_facing(&self, group: usize) -> Vec3 {
        let cells: Vec<(usize, usize)> = (0..self.rows)
            .flat_map(|r| (0..self.cols).map(move |c| (r, c)))
            .filter(|&(r, c)| self.group_of(r, c) == group)
            .collect();
        let sum = cells
            .iter()
            .fold(Vec3::ZERO, |s, &(r, c)| s + self.cell_facing(r, c));
        sum * (1.0 / cells.len() as f32)
    }

    /// Validates a configuration before rendering with it.
    pub fn check(&self) -> Result<(), String> {
        if self.rows < 16 || self.cols < 32 {
            return Err(format!(
                "the monitor needs at least 16x32 cells, got {}x{}",
                self.rows, self.cols
            ));
        }
        if !self.rows.is_multiple_of(self.group_rows) || !self.cols.is_multiple_of(self.group_cols)
        {
            return Err("shadow groups must divide the cell grid".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for i in 0..=255u32 {
            let v = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-5);
        }
    }

    #[test]
    fn screen_left_is_image_right() {
        let m = MonitorGeometry::default();
        assert!(m.cell_centre(0, 0).x > 0.0);
        assert!(m.cell_centre(0, m.cols - 1).x < 0.0);
        assert!(m.cell_centre(m.rows - 1, 0).y > m.cell_centre(0, 0).y);
    }

    #[test]
    fn the_dome_surrounds_the_head_with_its_left_at_image_right() {
        let m = MonitorGeometry::dome();
        let radius = |r, c| (m.cell_centre(r, c) - HEAD_REST).length();
        for (r, c) in [(0, 0), (7, 15), (15, 31)] {
            assert!((radius(r, c) - 1.0).abs() < 1e-5);
        }
        // Column 0 is nearly 90 degrees to the user's left (image right, +x),
        // the last column as far to the right, both level with the head.
        let (left, right) = (m.cell_centre(8, 0), m.cell_centre(8, m.cols - 1));
        assert!(left.x > 0.99 && right.x < -0.99, "{left:?} {right:?}");
        assert!((left.z - HEAD_REST.z).abs() < 0.1);
        // The middle is in front of the face, row 0 above it.
        assert!(m.cell_centre(8, 16).z < HEAD_REST.z - 0.99);
        assert!(m.cell_centre(0, 16).y < HEAD_REST.y - 0.6);
        // Each cell faces the head.
        let facing = m.cell_facing(3, 5);
        let towards_head = HEAD_REST - m.cell_centre(3, 5);
        let cos = facing.dot(towards_head) / (facing.length() * towards_head.length());
        assert!(cos > 0.9999, "{cos}");
    }

    #[test]
    fn the_dome_cells_cover_its_area_and_the_screen_is_unchanged() {
        let m = MonitorGeometry::dome();
        // 180 by 90 degrees of a unit sphere: pi * (sin 45 - sin -45).
        let area = std::f32::consts::PI * 2.0 * std::f32::consts::FRAC_1_SQRT_2;
        let cells: f32 = (0..m.rows)
            .flat_map(|r| (0..m.cols).map(move |c| (r, c)))
            .map(|(r, c)| m.cell_facing(r, c).length() * m.cell_area())
            .sum();
        assert!((cells - area).abs() < 1e-3 * area, "{cells} against {area}");
        assert!(m.cell_facing(0, 0).length() < m.cell_facing(8, 0).length());
        let desk = MonitorGeometry::default();
        assert_eq!(desk.cell_facing(3, 5), Vec3::new(0.0, 0.0, 1.0));
        assert_eq!(desk.group_facing(2), Vec3::new(0.0, 0.0, 1.0));
    }

    #[test]
    fn box_average_of_uniform_frame() {
        let mut f = RgbImage::new(64, 32);
        f.data.fill(255);
        let l = CellLight::from_frame(&f, 16, 32);
        assert!(l.rgb.iter().all(|v| (v.x - 1.0).abs() < 1e-6));
    }
}
