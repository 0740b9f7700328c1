//! Contour alignment: the last, sub-pixel step of a pose on the table. A part lying in a known
//! stable pose has three degrees of freedom left (x, y, yaw); its projected outline, computed
//! from the mesh, is pulled onto the image's intensity edges by a robust Gauss–Newton fit, as
//! industrial shape matching and model-based trackers (RAPID, ViSP's moving edges) do.
//!
//! Keypoints from a network place a 9 mm part to a pixel or two; the outline has hundreds of
//! edge samples, each measured to a fraction of a pixel, so it pins x, y and yaw far tighter.
//! It also decides near-symmetric parts' 180° ambiguity: both yaws are aligned, and the one
//! whose outline finds the image's edges (tabs, skirts) wins.

use std::collections::HashMap;

use image::DynamicImage;
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Vector2, Vector3};

use crate::Camera;
use crate::part::{Material, StablePose, TriMesh};

/// Settings of the contour fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourConfig {
    /// Search half-widths along the outline normals, pixels, one per round (coarse to fine).
    pub search_px: [f64; 3],
    /// Spacing of outline samples along the projected edges, pixels.
    pub spacing_px: f64,
    /// Smallest intensity step (0–1 grey levels per pixel) that counts as an edge.
    pub min_contrast: f32,
    /// Huber threshold of the residuals in the coarser rounds, pixels.
    pub huber_px: f64,
    /// Scale of the finest round's Cauchy weights, pixels: a residual r weighs
    /// 1 / (1 + (r / scale)²) there instead of Huber's, so once the outline sits within a pixel,
    /// a sample that took a step a pixel or more off (a face edge, a shadow, a neighbour)
    /// barely pulls. At the cells' densities, assembly-grade NIST pegs 71.0 → 75.1 % and USB-C
    /// 84.5 → 86.8 %, refined x / y 0.078 / 0.075 → 0.073 / 0.071 mm and 0.044 / 0.041 →
    /// 0.041 / 0.037 mm (0.5 px: 77.0 % and 87.0 %, but one fewer of 54 on the hard-light
    /// Cycles set, at the 0.1 mm edge). Redescending in every round, it let more NIST fits end
    /// in a wrong turn (36 → 41 more than 10° off), started pixels off.
    pub final_cauchy_px: f64,
    /// Gauss–Newton iterations per round.
    pub iterations: usize,
    /// Each outline sample takes the step nearest its predicted position among those at least
    /// this share of the strongest within reach: a part's own edge, not a stronger shadow or
    /// tag-board edge beyond it (1: always the strongest; 0.6 took the 90 % xy error of
    /// `contour_alignment` from 178 to 79 µm and the learned cell from 190 to 193 of 200).
    pub edge_share: f32,
    /// A fit is kept only if at least this share of its outline samples found an edge within
    /// one pixel; otherwise the keypoint pose stands.
    pub min_support: f64,
    /// Another hypothesis (the half-turn, a near-symmetric twin, the runner-up stable pose)
    /// replaces the keypoint pose only when its screened support is higher by this much: a
    /// near-symmetric outline fits its half-turn almost as well, while the keypoint net sees the
    /// details that break the symmetry (on the seed-2 test frames, 0.05 halved the half-turns
    /// of resting parts, 15 → 6 of 294; 0.2 let the keypoint pose stand on wrong stable poses).
    pub switch_margin: f64,
    /// A hypothesis in another stable pose than the best one so far replaces it only when its
    /// silhouette also covers the part's segmented pixels better by this much intersection over
    /// union ([`ContourAligner::mask_agreement`]): two stable poses can both find edges where
    /// one pose's outline ends on the other's inner rim (a square peg standing, its top and one
    /// side face in view, fits the longer top of one lying). On the cell-density eval sets the
    /// right stable pose went 94.9 → 97.1 % (NIST pegs) and 98.2 → 98.7 % (USB-C); margins of
    /// 0.07–0.12 did alike, and 0.2 let the keypoints' wrong stable poses stand on USB-C.
    pub mask_margin: f64,
    /// In the finest round, an outline of [`FinalEdge::Outermost`] takes the outermost step at
    /// least this share of the strongest within reach (0.3–0.6 all helped main shells on the
    /// four eval sets; 0.45 helped the most).
    pub outermost_share: f32,
    /// A screened fit that finds less than this share of its outline is screened again from
    /// starts around it ([`ContourAligner::screen_around`]).
    pub ring_below: f64,
    /// An outline that takes the nearest step ([`FinalEdge::Nearest`]) takes none whose
    /// outside, this many pixels out, the segmentation gives to the part itself
    /// ([`GreyPatch::with_mask_outside`]); 0 reads no mask. See the measurements there.
    pub mask_outside_px: f64,
}

impl Default for ContourConfig {
    fn default() -> Self {
        Self {
            search_px: [6.0, 3.0, 2.0],
            spacing_px: 2.0,
            min_contrast: 0.02,
            huber_px: 0.75,
            final_cauchy_px: 0.75,
            iterations: 4,
            edge_share: 0.6,
            min_support: 0.5,
            switch_margin: 0.05,
            mask_margin: 0.1,
            outermost_share: 0.45,
            ring_below: 0.9,
            mask_outside_px: 2.5,
        }
    }
}

impl ContourConfig {
    /// Whether `round` is the finest (last configured) one: where the outline's [`FinalEdge`]
    /// rule, hole weights and Cauchy weights apply.
    fn is_finest(&self, round: usize) -> bool {
        round + 1 == self.search_px.len()
    }

    /// The weight of a sample `r` pixels from its edge in `round`: Huber's in the coarser
    /// rounds, Cauchy's in the finest ([`Self::final_cauchy_px`]).
    fn residual_weight(&self, round: usize, r: f64) -> f64 {
        if self.is_finest(round) {
            cauchy_weight(r, self.final_cauchy_px)
        } else {
            huber_weight(r, self.huber_px)
        }
    }
}

/// Which intensity step an outline sample takes in the fit's finest round, once the outline
/// sits within a pixel or two of the part's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FinalEdge {
    /// The step nearest the predicted outline, as in the coarser rounds: right for solid parts,
    /// whose outline is their strongest edge nearby and whose shadows lie beyond it.
    #[default]
    Nearest,
    /// The outermost step at least [`ContourConfig::outermost_share`] of the strongest: for
    /// thin-walled sheet-metal shells, whose inner rims show a pixel or two inside the outline,
    /// often stronger than the outline against a light table, and would otherwise pull some
    /// sides of the fit inwards.
    Outermost,
}

impl FinalEdge {
    /// The rule for a part of this material: the outermost strong step for sheet-metal shells,
    /// whose inner rims show just inside the outline (on the four eval sets, main shells'
    /// seed-style |e_y| 0.09–0.14 → 0.08–0.11 mm); the nearest for solid parts, because a
    /// shadow's edge can lie just beyond their outline (insert molds lost 0.01 mm with the
    /// outermost one; the NIST pegs gained on square pegs and lost on round ones, 41.4 → 40.5 %
    /// assembly-grade).
    pub fn for_material(material: Material) -> Self {
        match material {
            Material::Metal => FinalEdge::Outermost,
            _ => FinalEdge::Nearest,
        }
    }
}

/// A part's outline model: its mesh with each edge's two triangles, in the part frame.
#[derive(Debug, Clone)]
pub struct PartOutline {
    final_edge: FinalEdge,
    hole_weight: f64,
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<Vector3<f64>>,
    /// Edges (a, b) with the triangles on either side (`u32::MAX` where there is only one).
    edges: Vec<([u32; 2], [u32; 2])>,
}

impl PartOutline {
    /// The outline model of `mesh` (closed, counter-clockwise seen from outside).
    pub fn new(mesh: &TriMesh) -> Self {
        let mut by_edge: HashMap<[u32; 2], [u32; 2]> = HashMap::new();
        let mut normals = Vec::with_capacity(mesh.triangles.len());
        for (ti, t) in mesh.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            normals.push((b - a).cross(&(c - a)));
            for k in 0..3 {
                let (i, j) = (t[k], t[(k + 1) % 3]);
                let slot = by_edge.entry([i.min(j), i.max(j)]).or_insert([u32::MAX; 2]);
                if slot[0] == u32::MAX {
                    slot[0] = ti as u32;
                } else {
                    slot[1] = ti as u32;
                }
            }
        }
        let mut edges: Vec<_> = by_edge.into_iter().collect();
        edges.sort_unstable();
        Self {
            final_edge: FinalEdge::default(),
            hole_weight: 1.0,
            vertices: mesh.vertices.clone(),
            triangles: mesh.triangles.clone(),
            normals,
            edges,
        }
    }

    /// The same outline, taking `rule`'s step in the finest round.
    pub fn with_final_edge(mut self, rule: FinalEdge) -> Self {
        self.final_edge = rule;
        self
    }

    /// The same outline, its samples on the edges of holes through the silhouette weighing
    /// `weight` times the others in the finest round, where they also take the nearest step
    /// (see [`crate::part::PartSpec::hole_weight`]).
    pub fn with_hole_weight(mut self, weight: f64) -> Self {
        self.hole_weight = weight;
        self
    }

    /// The projected outline of the part at `camera_T_part`, as pixels every `spacing` pixels
    /// along it: what the fit pulls onto the image's edges, for drawing it over the frame.
    #[allow(non_snake_case)]
    pub fn pixels(
        &self,
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
        spacing: f64,
    ) -> Vec<Point2<f64>> {
        self.outline(camera, camera_T_part, spacing, false)
            .into_iter()
            .map(|p| p.pixel)
            .collect()
    }

    /// The outline of the part at `camera_T_part`: points on the mesh whose projections lie on
    /// the boundary of the part's silhouette, every `spacing` pixels, with the outward normal
    /// (and, with `holes`, whether each borders a hole through the silhouette).
    #[allow(non_snake_case)]
    fn outline(
        &self,
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
        spacing: f64,
        holes: bool,
    ) -> Vec<OutlinePoint> {
        let Some((pixels, front, mask)) = self.silhouette(camera, camera_T_part) else {
            return Vec::new();
        };
        let hole_map = if holes { mask.holes() } else { Vec::new() };
        let mut out = Vec::new();
        for ([a, b], [ta, tb]) in &self.edges {
            let fa = front[*ta as usize];
            let fb = if *tb == u32::MAX {
                !fa
            } else {
                front[*tb as usize]
            };
            if fa == fb {
                continue;
            }
            let (pa, pb) = (pixels[*a as usize], pixels[*b as usize]);
            let d = pb - pa;
            let len = d.norm();
            if len < 1e-9 {
                continue;
            }
            let normal = Vector2::new(d.y, -d.x) / len;
            let n = (len / spacing).ceil().max(1.0) as usize;
            for s in 0..n {
                let t = (s as f64 + 0.5) / n as f64;
                let pixel = pa + d * t;
                let (inside_plus, inside_minus) = (
                    mask.inside(pixel + normal * 1.5),
                    mask.inside(pixel - normal * 1.5),
                );
                let outward = match (inside_plus, inside_minus) {
                    (false, true) => normal,
                    (true, false) => -normal,
                    _ => continue,
                };
                let (va, vb) = (self.vertices[*a as usize], self.vertices[*b as usize]);
                out.push(OutlinePoint {
                    part: va + (vb - va) * t,
                    pixel,
                    normal: outward,
                    open: (2..=OPEN_PX as usize).all(|k| !mask.inside(pixel + outward * k as f64)),
                    hole: mask
                        .cell(pixel + outward * 1.5)
                        .is_some_and(|k| hole_map.get(k) == Some(&true)),
                });
            }
        }
        out
    }

    /// The part at `camera_T_part` as `camera` sees it: its vertices' pixels, which triangles
    /// face the camera, and the silhouette they cover (`None` when it does not fit on a sensor).
    #[allow(non_snake_case)]
    fn silhouette(
        &self,
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
    ) -> Option<(Vec<Point2<f64>>, Vec<bool>, Silhouette)> {
        let pixels = self
            .vertices
            .iter()
            .map(|v| camera.project(&(camera_T_part * v)).ok())
            .collect::<Option<Vec<Point2<f64>>>>()?;
        let front: Vec<bool> = self
            .triangles
            .iter()
            .zip(&self.normals)
            .map(|(t, n)| {
                let p = camera_T_part * self.vertices[t[0] as usize];
                (camera_T_part.rotation * n).dot(&p.coords) < 0.0
            })
            .collect();
        let mask = Silhouette::rasterise(&pixels, &self.triangles, &front)?;
        Some((pixels, front, mask))
    }
}

/// One outline sample: where on the part, where in the image, and which way is out.
#[derive(Debug, Clone, Copy)]
struct OutlinePoint {
    part: Point3<f64>,
    pixel: Point2<f64>,
    normal: Vector2<f64>,
    /// Borders a hole through the silhouette (only where asked for).
    hole: bool,
    /// Nothing of the part lies within [`OPEN_PX`] outside it: no concavity whose far side a
    /// segmentation of coarse cells would fill.
    open: bool,
}

/// How far outside an outline sample the silhouette must be clear for the segmentation to be
/// read there ([`GreyPatch::with_mask_outside`]), pixels: three segmenter cells at the nets'
/// scale.
const OPEN_PX: f64 = 12.0;

/// The projected part as a binary mask on the pixel grid (pixel centres at integers).
struct Silhouette {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    cells: Vec<bool>,
}

impl Silhouette {
    /// Largest mask side, pixels: a part seen from so close is not what the fit is for.
    const MAX_SIDE: usize = 1024;

    fn rasterise(pixels: &[Point2<f64>], triangles: &[[u32; 3]], front: &[bool]) -> Option<Self> {
        let (mut lo, mut hi) = (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN));
        for p in pixels {
            lo = lo.inf(&p.coords);
            hi = hi.sup(&p.coords);
        }
        // Sized in floating point first: a wild pose's pixels overflow integers.
        let span = hi - lo;
        let side = Self::MAX_SIDE as f64;
        if !(span.x < side && span.y < side && lo.x.abs() < 1e9 && lo.y.abs() < 1e9) {
            return None;
        }
        let (x0, y0) = (lo.x.floor() as i64 - 3, lo.y.floor() as i64 - 3);
        let width = (hi.x.ceil() as i64 + 4 - x0) as usize;
        let height = (hi.y.ceil() as i64 + 4 - y0) as usize;
        if width > Self::MAX_SIDE || height > Self::MAX_SIDE {
            return None;
        }
        let mut cells = vec![false; width * height];
        for (t, _) in triangles.iter().zip(front).filter(|(_, f)| **f) {
            let corners = t.map(|i| pixels[i as usize]);
            let [a, b, c] = corners;
            if cross(b - a, c - a).abs() < 1e-12 {
                continue;
            }
            let (ylo, yhi) = (a.y.min(b.y).min(c.y), a.y.max(b.y).max(c.y));
            for i in ylo.ceil() as i64..=yhi.floor() as i64 {
                // The row's span inside the triangle, edges included: where it crosses the sides.
                let y = i as f64;
                let (mut xl, mut xr) = (f64::INFINITY, f64::NEG_INFINITY);
                for k in 0..3 {
                    let (p, q) = (corners[k], corners[(k + 1) % 3]);
                    if (p.y - y) * (q.y - y) > 0.0 {
                        continue;
                    }
                    let xs = if p.y == q.y {
                        [p.x, q.x]
                    } else {
                        let x = p.x + (y - p.y) * (q.x - p.x) / (q.y - p.y);
                        [x, x]
                    };
                    xl = xl.min(xs[0]).min(xs[1]);
                    xr = xr.max(xs[0]).max(xs[1]);
                }
                if xl > xr {
                    continue;
                }
                let row = (i - y0) as usize * width;
                let (j0, j1) = (
                    (xl.ceil() as i64 - x0) as usize,
                    (xr.floor() as i64 - x0) as usize,
                );
                if j0 <= j1 {
                    cells[row + j0..=row + j1].fill(true);
                }
            }
        }
        Some(Self {
            x0,
            y0,
            width,
            height,
            cells,
        })
    }

    /// The holes through the mask, cell by cell: the outside cells that the border's flood fill
    /// does not reach (the margin ring around the mask connects all the others).
    fn holes(&self) -> Vec<bool> {
        let (width, height) = (self.width, self.height);
        let mut hole: Vec<bool> = self.cells.iter().map(|c| !c).collect();
        let mut stack = vec![0usize];
        hole[0] = false;
        while let Some(k) = stack.pop() {
            let (i, j) = (k / width, k % width);
            let neighbours = [
                (i > 0).then(|| k - width),
                (i + 1 < height).then(|| k + width),
                (j > 0).then(|| k - 1),
                (j + 1 < width).then(|| k + 1),
            ];
            for n in neighbours.into_iter().flatten() {
                if hole[n] {
                    hole[n] = false;
                    stack.push(n);
                }
            }
        }
        hole
    }

    /// The cell under pixel `p`, if the mask's grid covers it.
    fn cell(&self, p: Point2<f64>) -> Option<usize> {
        let (j, i) = (p.x.round() as i64 - self.x0, p.y.round() as i64 - self.y0);
        (i >= 0 && j >= 0 && (i as usize) < self.height && (j as usize) < self.width)
            .then(|| i as usize * self.width + j as usize)
    }

    fn inside(&self, p: Point2<f64>) -> bool {
        self.cell(p).is_some_and(|k| self.cells[k])
    }
}

fn cross(a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Longest search along a normal, pixels.
const MAX_REACH: usize = 16;

/// Which part the segmentation says a pixel of the frame shows, as seen from the part being
/// fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Owner {
    /// No part: the table, or nothing was segmented.
    #[default]
    Nobody,
    /// The part being fitted.
    Me,
    /// Another part, which hides the fitted one there.
    Other,
}

/// A grey-level window of the frame (0–1), sampled bilinearly in sensor pixels, and which part
/// the segmentation says each of its pixels shows.
pub struct GreyPatch {
    origin: [f64; 2],
    width: usize,
    height: usize,
    values: Vec<f32>,
    /// Per pixel, its owner (empty: nothing segmented).
    owners: Vec<Owner>,
    /// How far outside an intensity step the owners are read, pixels; `None` when they are
    /// not ([`GreyPatch::with_mask_outside`]).
    mask_outside_px: Option<f64>,
}

impl GreyPatch {
    /// The grey levels of `image` (whose top-left pixel is sensor pixel `image_origin`) in the
    /// sensor-pixel box `[x, y, width, height]`, clipped to the image.
    pub fn cut(image: &DynamicImage, image_origin: [u32; 2], sensor_box: [i64; 4]) -> Self {
        let x = (sensor_box[0] - i64::from(image_origin[0])).clamp(0, i64::from(image.width()));
        let y = (sensor_box[1] - i64::from(image_origin[1])).clamp(0, i64::from(image.height()));
        let w = sensor_box[2].min(i64::from(image.width()) - x).max(0);
        let h = sensor_box[3].min(i64::from(image.height()) - y).max(0);
        let grey = image
            .crop_imm(x as u32, y as u32, w as u32, h as u32)
            .to_luma32f();
        Self {
            origin: [
                (x + i64::from(image_origin[0])) as f64,
                (y + i64::from(image_origin[1])) as f64,
            ],
            width: w as usize,
            height: h as usize,
            values: grey.into_raw(),
            owners: Vec::new(),
            mask_outside_px: None,
        }
    }

    /// The same patch with each pixel's owner: `owners(y, x, row)` fills `row` with those of
    /// sensor row `y` from column `x` on. Screening fits no outline sample where another part
    /// covers the fitted one and no support counts one there; the pixels it owns are its mask
    /// ([`ContourAligner::mask_agreement`]).
    pub fn with_owners(mut self, owners: impl Fn(i64, i64, &mut [Owner])) -> Self {
        let (x0, y0) = (self.origin[0] as i64, self.origin[1] as i64);
        self.owners = vec![Owner::Nobody; self.width * self.height];
        if self.width > 0 {
            for (i, row) in self.owners.chunks_exact_mut(self.width).enumerate() {
                owners(y0 + i as i64, x0, row);
            }
        }
        self
    }

    /// The same patch, whose edge search takes no intensity step for the outline of a part
    /// whose outside, `depth_px` pixels out, the segmentation gives to the part itself: that
    /// step is an edge between two of its faces (the rim of a peg's end, a standing peg's top
    /// against its sides), which can lie nearer the predicted outline than the outline itself.
    /// Read only where the silhouette is clear well beyond `depth_px` (a concavity narrower
    /// than the segmenter's cells is filled in its mask) and for outlines that take the
    /// nearest step. Without a pixel of the part in the patch, or at 0, nothing is read.
    ///
    /// On the cell-density eval sets (`cell eval`, 100 frames, seed 4), 2.5 px took the NIST
    /// pegs' assembly-grade poses from 693 to 819 of about 1 150 and their refined x / y from
    /// 0.11 / 0.10 to 0.08 / 0.07 mm, and USB-C's insert molds from 174 to 179 of 199 (2 px:
    /// 828 and 176; 3 px: 810 and 180). Sheet-metal shells, whose outermost rule already
    /// looks past their inner rims, lost with it (main shells 212 → 201–207 of 262), and
    /// reading the inside too (no table just inside a step: the outer edge of a shadow) gained
    /// nothing.
    pub fn with_mask_outside(mut self, depth_px: f64) -> Self {
        self.mask_outside_px =
            (depth_px > 0.0 && self.owners.contains(&Owner::Me)).then_some(depth_px);
        self
    }

    /// The owner of the pixel nearest sensor point `p`; `None` outside the patch or where
    /// nothing was segmented.
    fn owner(&self, p: Point2<f64>) -> Option<Owner> {
        if self.owners.is_empty() {
            return None;
        }
        let (u, v) = (
            (p.x - self.origin[0]).round(),
            (p.y - self.origin[1]).round(),
        );
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (j, i) = (u as usize, v as usize);
        (j < self.width && i < self.height).then(|| self.owners[i * self.width + j])
    }

    /// Whether the pixel nearest sensor point `p` is covered by another part.
    fn is_hidden(&self, p: Point2<f64>) -> bool {
        self.owner(p) == Some(Owner::Other)
    }

    /// Whether the segmentation lets a step at `p`, whose outside is along `normal`, be the
    /// fitted part's outline ([`Self::with_mask_outside`]).
    fn outside_agrees(&self, p: Point2<f64>, normal: Vector2<f64>) -> bool {
        self.mask_outside_px
            .is_none_or(|depth| self.owner(p + normal * depth) != Some(Owner::Me))
    }

    /// Bilinear grey level at a sensor pixel, or `None` outside the patch.
    fn sample(&self, p: Point2<f64>) -> Option<f32> {
        let (u, v) = (p.x - self.origin[0], p.y - self.origin[1]);
        // Bounds in floating point: a wild pose projects to coordinates that no integer holds
        // (a cast saturates, and one more would wrap).
        if !(u >= 0.0 && v >= 0.0 && u + 1.0 < self.width as f64 && v + 1.0 < self.height as f64) {
            return None;
        }
        // Truncation is the floor here (both are non-negative), without a libm call.
        let (j, i) = (u as usize, v as usize);
        let (fu, fv) = ((u - j as f64) as f32, (v - i as f64) as f32);
        let at = |i: usize, j: usize| self.values[i * self.width + j];
        let top = at(i, j) * (1.0 - fu) + at(i, j + 1) * fu;
        let bottom = at(i + 1, j) * (1.0 - fu) + at(i + 1, j + 1) * fu;
        Some(top * (1.0 - fv) + bottom * fv)
    }

    /// The intensity step along `normal` within `reach` pixels of `pixel` among the local peaks
    /// at least `share` of the strongest, the one nearest `pixel` (or, with `rule`
    /// [`FinalEdge::Outermost`], the farthest along `normal`): its sub-pixel offset along the
    /// normal and its contrast. With `read_mask`, only the steps whose outside the mask allows
    /// ([`Self::with_mask_outside`]) count, the strongest of them included.
    fn edge_along(
        &self,
        pixel: Point2<f64>,
        normal: Vector2<f64>,
        reach: f64,
        share: f32,
        rule: FinalEdge,
        read_mask: bool,
    ) -> Option<(f64, f32)> {
        let n = reach.ceil() as i64;
        // Grey levels half a pixel either side of each step, shared by neighbouring steps.
        let mut levels = [0f32; 2 * MAX_REACH + 2];
        let count = (2 * n + 2) as usize;
        if count > levels.len() {
            return None;
        }
        for (k, level) in levels[..count].iter_mut().enumerate() {
            *level = self.sample(pixel + normal * (k as f64 - n as f64 - 0.5))?;
        }
        let mut buffer = [0f32; 2 * MAX_REACH + 1];
        let steps = &mut buffer[..count - 1];
        for (step, w) in steps.iter_mut().zip(levels[..count].windows(2)) {
            *step = (w[1] - w[0]).abs();
        }
        let steps = &*steps;
        // Whether the segmentation lets step `k` be the outline, read only where it matters.
        let read_mask = read_mask && self.mask_outside_px.is_some();
        let admits = |k: usize| {
            !read_mask || self.outside_agrees(pixel + normal * (k as f64 - n as f64), normal)
        };
        // The strongest step it admits: the strongest of all, unless that one is ruled out.
        let (strongest, top) = steps
            .iter()
            .enumerate()
            .fold((0, 0f32), |m, (k, &s)| if s > m.1 { (k, s) } else { m });
        let top = if admits(strongest) {
            top
        } else {
            (0..steps.len())
                .filter(|&k| admits(k))
                .map(|k| steps[k])
                .fold(0f32, f32::max)
        };
        let bar = share * top;
        // The step nearest the predicted outline among the admitted peaks at least `bar` strong.
        let (k, &best) = steps
            .iter()
            .enumerate()
            .filter(|(k, s)| {
                **s >= bar
                    && (*k == 0 || steps[k - 1] <= **s)
                    && (k + 1 == steps.len() || steps[k + 1] <= **s)
                    && admits(*k)
            })
            .min_by(|a, b| match rule {
                FinalEdge::Nearest => {
                    let d = |k: usize| (k as f64 - n as f64).abs();
                    d(a.0).total_cmp(&d(b.0)).then(b.1.total_cmp(a.1))
                }
                FinalEdge::Outermost => b.0.cmp(&a.0),
            })?;
        // Parabolic peak through the neighbours (the ends keep the grid offset).
        let mut offset = k as f64 - n as f64;
        if k > 0 && k + 1 < steps.len() {
            let (l, r) = (f64::from(steps[k - 1]), f64::from(steps[k + 1]));
            let denom = l - 2.0 * f64::from(best) + r;
            if denom < 0.0 {
                offset += (0.5 * (l - r) / denom).clamp(-0.5, 0.5);
            }
        }
        (offset.abs() <= reach).then_some((offset, best))
    }
}

/// A contour-aligned pose on one stable pose: `stable.table_T_part(x, y, yaw)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourFit {
    /// Table x, metres.
    pub x: f64,
    /// Table y, metres.
    pub y: f64,
    /// Yaw about the table normal, radians.
    pub yaw: f64,
    /// Share of the outline samples in sight (not hidden by other parts) that found an edge
    /// within one pixel at the end.
    pub support: f64,
}

impl ContourFit {
    /// How far to trust the fit, in [0, 1]: 0 at a support of `min_support` or less, rising
    /// quadratically to 1 at full support. Right fits find nearly all their edges (on the
    /// seed-2 and test frames, 90 % of right fits of resting parts have a support above 0.91),
    /// fits that settled on a neighbour's or a shadow's edges miss many (0.6–0.8), so this
    /// weighs the pose's confidence and the cell picks parts whose outline it found.
    pub fn quality(&self, min_support: f64) -> f64 {
        let span = (1.0 - min_support).max(1e-9);
        ((self.support - min_support) / span)
            .clamp(0.0, 1.0)
            .powi(2)
    }
}

/// What a fit aligns: a part's outline lying in one of its stable poses, seen by a camera,
/// and the grey levels of the frame around it.
#[derive(Clone, Copy)]
pub struct ContourView<'a> {
    /// The part's outline model.
    pub outline: &'a PartOutline,
    /// The stable pose it lies in.
    pub stable: &'a StablePose,
    /// The camera (whole sensor).
    pub camera: &'a Camera,
    /// The frame's grey levels around the part.
    pub patch: &'a GreyPatch,
}

/// Aligns part outlines with image edges on a calibrated table.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
pub struct ContourAligner {
    camera_T_table: Isometry3<f64>,
    config: ContourConfig,
}

impl ContourAligner {
    /// An aligner for the table at `camera_T_table`.
    #[allow(non_snake_case)]
    pub fn new(camera_T_table: Isometry3<f64>, config: ContourConfig) -> Self {
        Self {
            camera_T_table,
            config,
        }
    }

    /// The fit's settings.
    pub fn config(&self) -> &ContourConfig {
        &self.config
    }

    /// Fits x, y and yaw of the part in `view` so its outline meets the frame's edges,
    /// starting from `(x, y, yaw)`. `None` when too few samples find edges.
    pub fn align(&self, view: ContourView<'_>, start: (f64, f64, f64)) -> Option<ContourFit> {
        self.rounds(view, start, 0..self.config.search_px.len())
    }

    /// The first, coarsest round of [`Self::align`] only, on the outline samples in sight: a
    /// cheap fit whose support ranks competing hypotheses before the best one is finished with
    /// [`Self::finish`].
    pub fn screen(&self, view: ContourView<'_>, start: (f64, f64, f64)) -> Option<ContourFit> {
        self.rounds(view, start, 0..1)
    }

    /// The remaining rounds of [`Self::align`] from a [`Self::screen`]ed fit.
    pub fn finish(&self, view: ContourView<'_>, screened: &ContourFit) -> Option<ContourFit> {
        let start = (screened.x, screened.y, screened.yaw);
        self.rounds(view, start, 1..self.config.search_px.len())
    }

    /// How well the silhouette of the part in `view` at `fit` covers the pixels the segmentation
    /// gave it, as their intersection over union on the pixels of the patch that no other part
    /// covers; `None` when the patch has no pixel of the part. Two stable poses whose outlines
    /// both find edges (a square peg standing shows its top and one side face, lying a longer
    /// top whose rim is where the standing one's outline ends) differ in the area they cover.
    #[allow(non_snake_case)]
    pub fn mask_agreement(&self, view: ContourView<'_>, fit: &ContourFit) -> Option<f64> {
        let patch = view.patch;
        let pose = self.camera_T_table * view.stable.table_T_part(fit.x, fit.y, fit.yaw);
        let (_, _, shape) = view.outline.silhouette(view.camera, &pose)?;
        let (x0, y0) = (patch.origin[0] as i64, patch.origin[1] as i64);
        let (mut both, mut either, mut mine) = (0usize, 0usize, 0usize);
        for (k, owner) in patch.owners.iter().enumerate() {
            let (i, j) = ((k / patch.width) as i64, (k % patch.width) as i64);
            let me = match owner {
                Owner::Other => continue,
                Owner::Me => true,
                Owner::Nobody => false,
            };
            let inside = shape.inside(Point2::new((x0 + j) as f64, (y0 + i) as f64));
            mine += usize::from(me);
            both += usize::from(me && inside);
            either += usize::from(me || inside);
        }
        (mine > 0).then(|| both as f64 / either as f64)
    }

    /// Screens the part in `view` again from starts around a screened `fit` ([`RING_STARTS`]
    /// directions at each of [`RING_REACHES`] coarse reaches on the table, in its yaw) and
    /// returns the one that finds the most of its outline; `None` when none fits. For a fit
    /// that finds too little of its outline ([`ContourConfig::ring_below`]) because part of it
    /// lay beyond the coarse reach from the start: a peg on its side whose keypoints sit a
    /// millimetre along its axis fits its long sides and never sees its ends.
    #[allow(non_snake_case)]
    pub fn screen_around(&self, view: ContourView<'_>, fit: &ContourFit) -> Option<ContourFit> {
        let reach_m =
            self.config.search_px[0] / view.camera.table_px_per_mm(&self.camera_T_table) * 1e-3;
        // The starts are the fit moved a few pixels: one outline, found at the fit, serves all.
        let centre = Vector3::new(fit.x, fit.y, fit.yaw);
        let points = view.outline.outline(
            view.camera,
            &self.pose(&view, &centre),
            self.config.spacing_px,
            false,
        );
        let starts = RING_REACHES.iter().flat_map(|r| {
            (0..RING_STARTS).map(move |k| {
                let a = std::f64::consts::TAU * k as f64 / RING_STARTS as f64;
                centre + Vector3::new(a.cos(), a.sin(), 0.0) * (r * reach_m)
            })
        });
        starts
            .filter_map(|start| {
                let q = self.descend(&view, &points, start, 0, true)?;
                self.supported(&view, q)
            })
            // The nearest start of those that find the most (the first of equals).
            .reduce(|best, fit| {
                if fit.support > best.support {
                    fit
                } else {
                    best
                }
            })
    }

    /// `camera_T_part` of the part in `view` at table (x, y, yaw) `q`.
    #[allow(non_snake_case)]
    fn pose(&self, view: &ContourView<'_>, q: &Vector3<f64>) -> Isometry3<f64> {
        self.camera_T_table * view.stable.table_T_part(q.x, q.y, q.z)
    }

    /// Gauss–Newton rounds `which` of the configured search reaches, then the fit's support. In
    /// the finest (last configured) round the outline's [`FinalEdge`] rule picks the steps.
    fn rounds(
        &self,
        view: ContourView<'_>,
        start: (f64, f64, f64),
        which: std::ops::Range<usize>,
    ) -> Option<ContourFit> {
        let mut q = Vector3::new(start.0, start.1, start.2);
        // Screening starts from keypoint poses pixels off, where the edges of the parts covering
        // this one would rank its hypotheses, so it fits only the samples in sight. The later
        // rounds start within a pixel or two, where a touching neighbour's edge is mostly this
        // part's own too, and fit every sample (skipping them there lost accuracy).
        let screening = which == (0..1);
        for round in which {
            // The outline is re-found once per round; within a round its points move with the pose.
            // Holes are told apart only where they weigh more: in the finest round.
            let holes = self.config.is_finest(round) && view.outline.hole_weight != 1.0;
            let points = view.outline.outline(
                view.camera,
                &self.pose(&view, &q),
                self.config.spacing_px,
                holes,
            );
            q = self.descend(&view, &points, q, round, screening)?;
        }
        self.supported(&view, q)
    }

    /// One round's Gauss–Newton iterations of the outline `points` (found once, moving with the
    /// pose) from table (x, y, yaw) `q` onto the edges within the round's reach; with
    /// `screening`, on the samples in sight only. `None` when too few samples find edges.
    #[allow(non_snake_case)]
    fn descend(
        &self,
        view: &ContourView<'_>,
        points: &[OutlinePoint],
        mut q: Vector3<f64>,
        round: usize,
        screening: bool,
    ) -> Option<Vector3<f64>> {
        let ContourView {
            outline,
            stable,
            camera,
            patch,
        } = *view;
        let camera_r_table = *self.camera_T_table.rotation.to_rotation_matrix().matrix();
        let reach = self.config.search_px[round];
        let (share, rule) = match outline.final_edge {
            FinalEdge::Outermost if self.config.is_finest(round) => {
                (self.config.outermost_share, FinalEdge::Outermost)
            }
            _ => (self.config.edge_share, FinalEdge::Nearest),
        };
        // The mask's outside is read for outlines that take the nearest step, where the
        // silhouette is clear beyond the sample ([`GreyPatch::with_mask_outside`]).
        let read_mask = outline.final_edge == FinalEdge::Nearest;
        for _ in 0..self.config.iterations {
            let table_T_part = stable.table_T_part(q.x, q.y, q.z);
            let (mut h, mut g) = (Matrix3::zeros(), Vector3::zeros());
            let mut used = 0;
            for p in points {
                // d(table point)/d(x, y, yaw): the yaw turns it about the vertical through (x, y).
                let t = table_T_part * p.part;
                let d_table =
                    Matrix3::new(1.0, 0.0, -(t.y - q.y), 0.0, 1.0, t.x - q.x, 0.0, 0.0, 0.0);
                let Ok((pixel, d_pixel)) = camera.project_with_jacobian(&(self.camera_T_table * t))
                else {
                    continue;
                };
                if screening && patch.is_hidden(pixel) {
                    continue;
                }
                // A hole's edge is a single clean step: the nearest one, weighed more.
                let (share, rule, weight) = if p.hole {
                    (
                        self.config.edge_share,
                        FinalEdge::Nearest,
                        outline.hole_weight,
                    )
                } else {
                    (share, rule, 1.0)
                };
                let Some((offset, contrast)) =
                    patch.edge_along(pixel, p.normal, reach, share, rule, read_mask && p.open)
                else {
                    continue;
                };
                if contrast < self.config.min_contrast {
                    continue;
                }
                let j = (p.normal.transpose() * d_pixel * camera_r_table * d_table).transpose();
                // Residual: signed distance from the predicted outline to the edge.
                let r = -offset;
                let w = weight * self.config.residual_weight(round, r);
                h += j * j.transpose() * w;
                g += j * (r * w);
                used += 1;
            }
            if used < 12 {
                return None;
            }
            let step = h.try_inverse()? * -g;
            q += step;
            if step.xy().norm() < 1e-8 && step.z.abs() < 1e-6 {
                break;
            }
        }
        Some(q)
    }

    /// The fit at table (x, y, yaw) `q` with its support: the share of its outline samples in
    /// sight whose strongest step within a pixel is an edge. `None` when none is in sight. The
    /// image alone decides it: reading the mask's outside here too made fewer fits confident
    /// enough to pick (NIST pegs' eval set, 974 → 927 at 4 px) and the picks no better.
    fn supported(&self, view: &ContourView<'_>, q: Vector3<f64>) -> Option<ContourFit> {
        let patch = view.patch;
        let mut points = view.outline.outline(
            view.camera,
            &self.pose(view, &q),
            self.config.spacing_px,
            false,
        );
        points.retain(|p| !patch.is_hidden(p.pixel));
        if points.is_empty() {
            return None;
        }
        let hits = points
            .iter()
            .filter_map(|p| {
                patch.edge_along(p.pixel, p.normal, 1.0, 1.0, FinalEdge::Nearest, false)
            })
            .filter(|(_, c)| *c >= self.config.min_contrast)
            .count();
        Some(ContourFit {
            x: q.x,
            y: q.y,
            yaw: q.z,
            support: hits as f64 / points.len() as f64,
        })
    }
}

/// Directions of [`ContourAligner::screen_around`]'s starts.
pub const RING_STARTS: usize = 8;

/// Radii of [`ContourAligner::screen_around`]'s starts, in coarse reaches
/// ([`ContourConfig::search_px`]'s first).
pub const RING_REACHES: [f64; 2] = [1.0, 2.0];

/// Huber's weight of residual `r` at threshold `k`: full within it, a constant pull beyond.
fn huber_weight(r: f64, k: f64) -> f64 {
    if r.abs() <= k { 1.0 } else { k / r.abs() }
}

/// Cauchy's weight of residual `r` at `scale`: a pull that fades once past it.
fn cauchy_weight(r: f64, scale: f64) -> f64 {
    1.0 / (1.0 + (r / scale).powi(2))
}

#[cfg(test)]
mod tests {
    use image::{GrayImage, Luma};
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    #[test]
    fn a_patch_samples_nothing_outside_it_however_far() {
        let image = DynamicImage::ImageLuma8(GrayImage::from_pixel(8, 6, Luma([255])));
        let patch = GreyPatch::cut(&image, [100, 200], [100, 200, 8, 6]);
        assert_eq!(patch.sample(Point2::new(103.5, 202.5)), Some(1.0));
        // The last pixel centre that has a right and a lower neighbour, and just beyond it.
        assert_eq!(patch.sample(Point2::new(106.99, 204.99)), Some(1.0));
        assert_eq!(patch.sample(Point2::new(107.0, 203.0)), None);
        assert_eq!(patch.sample(Point2::new(103.0, 205.0)), None);
        // A wild pose's projections: these once saturated a cast and wrapped an index.
        for far in [1e30, f64::INFINITY, -1e30, f64::NAN, 1.8e19, 9.3e18] {
            assert_eq!(patch.sample(Point2::new(far, 203.0)), None, "{far}");
            assert_eq!(patch.sample(Point2::new(103.0, far)), None, "{far}");
        }
    }

    #[test]
    fn a_silhouette_far_off_the_sensor_is_not_rasterised() {
        let triangle =
            |a: Point2<f64>| [a, a + Vector2::new(20.0, 0.0), a + Vector2::new(0.0, 20.0)];
        let raster =
            |corners: [Point2<f64>; 3]| Silhouette::rasterise(&corners, &[[0, 1, 2]], &[true]);
        let near = raster(triangle(Point2::new(500.0, 300.0))).expect("an ordinary triangle");
        assert!(near.cells.iter().filter(|c| **c).count() > 150);
        for far in [1e30, -1e30, 9.3e18, f64::INFINITY, f64::NAN] {
            assert!(raster(triangle(Point2::new(far, 300.0))).is_none(), "{far}");
            assert!(raster(triangle(Point2::new(300.0, far))).is_none(), "{far}");
        }
    }

    /// A 9 × 5 × 3 mm box lying on its largest face, seen from 1.5 m straight above by the
    /// seed's camera: a bright rectangle on a dark table, drawn with exact area coverage
    /// (16 × 16 samples per pixel) and no noise.
    fn scene(
        x: f64,
        y: f64,
        yaw: f64,
    ) -> (PartOutline, StablePose, Camera, Isometry3<f64>, GreyPatch) {
        scene_shaded(x, y, yaw, None, |inset_px, _| {
            40 + (inset_px >= 0.0) as u32 * 160
        })
    }

    /// The box of [`scene`], with a centred `window` (x and y sizes, m) cut through it if asked
    /// for, its grey level 0–255 given by `shade` of how far inside the outer outline a point is
    /// (pixels; negative outside) and where it is on the top face (part frame, m), each pixel
    /// the mean over 16 × 16 samples.
    #[allow(non_snake_case)]
    fn scene_shaded(
        x: f64,
        y: f64,
        yaw: f64,
        window: Option<Vector2<f64>>,
        shade: impl Fn(f64, Point2<f64>) -> u32,
    ) -> (PartOutline, StablePose, Camera, Isometry3<f64>, GreyPatch) {
        let (size, h) = (Vector2::new(9e-3, 5e-3), 3e-3);
        let mesh = match window {
            None => TriMesh::cuboid(Vector3::new(size.x, size.y, h)),
            // Four bars around the window: two full-length ones beyond it in y, two between.
            Some(w) => {
                let (side, end) = ((size.y - w.y) / 2.0, (size.x - w.x) / 2.0);
                let bar = |sx: f64, sy: f64, cx: f64, cy: f64| {
                    TriMesh::cuboid(Vector3::new(sx, sy, h))
                        .transformed(&Isometry3::translation(cx, cy, 0.0))
                };
                let mut mesh = bar(size.x, side, 0.0, (w.y + side) / 2.0);
                mesh.append(&bar(size.x, side, 0.0, -(w.y + side) / 2.0));
                mesh.append(&bar(end, w.y, (w.x + end) / 2.0, 0.0));
                mesh.append(&bar(end, w.y, -(w.x + end) / 2.0, 0.0));
                mesh
            }
        };
        let stable = StablePose {
            name: "+z".into(),
            probability: 1.0,
            up_in_part: [0.0, 0.0, 1.0],
            rotation: [0.0; 3],
            rest_height: 1.5e-3,
        };
        let camera = Camera::basler_seed();
        let camera_T_table = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
        .inverse();
        let camera_T_part = camera_T_table * stable.table_T_part(x, y, yaw);
        let centre = camera.project(&(camera_T_part * Point3::origin())).unwrap();
        let (x0, y0) = (centre.x.round() as i64 - 60, centre.y.round() as i64 - 60);
        // The top face's corners; the box is seen from straight above, so that is its outline
        // up to the walls' sliver of perspective (< 0.02 px here, near the optical axis).
        let corners: Vec<Point2<f64>> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|(sx, sy)| {
                let p = Point3::new(sx * 4.5e-3, sy * 2.5e-3, 1.5e-3);
                camera.project(&(camera_T_part * p)).unwrap()
            })
            .collect();
        // How far inside the convex outline a point is: its least signed distance to the four
        // edges (the winding is the same for all four).
        let winding = cross(corners[1] - corners[0], corners[2] - corners[0]).signum();
        let inset = |p: Point2<f64>| {
            (0..4)
                .map(|k| {
                    let (a, b) = (corners[k], corners[(k + 1) % 4]);
                    winding * cross(b - a, p - a) / (b - a).norm()
                })
                .fold(f64::INFINITY, f64::min)
        };
        // Where a pixel is on the top face: the projection is affine to well under a hundredth
        // of a pixel this near the optical axis.
        let (u, v) = (corners[1] - corners[0], corners[3] - corners[0]);
        let on_face = |p: Point2<f64>| {
            let d = p - corners[0];
            let det = cross(u, v);
            let (a, b) = (cross(d, v) / det, cross(u, d) / det);
            Point2::new((a - 0.5) * size.x, (b - 0.5) * size.y)
        };
        let mut img = GrayImage::new(120, 120);
        for (j, i, px) in img.enumerate_pixels_mut() {
            let mut sum = 0;
            for s in 0..16 {
                for t in 0..16 {
                    let p = Point2::new(
                        (x0 + i64::from(j)) as f64 - 0.5 + (f64::from(s) + 0.5) / 16.0,
                        (y0 + i64::from(i)) as f64 - 0.5 + (f64::from(t) + 0.5) / 16.0,
                    );
                    sum += shade(inset(p), on_face(p));
                }
            }
            *px = Luma([(sum / 256) as u8]);
        }
        let patch = GreyPatch::cut(
            &DynamicImage::ImageLuma8(img),
            [x0 as u32, y0 as u32],
            [x0, y0, 120, 120],
        );
        (
            PartOutline::new(&mesh),
            stable,
            camera,
            camera_T_table,
            patch,
        )
    }

    #[test]
    #[allow(non_snake_case)]
    fn the_outline_of_a_box_seen_from_above_is_its_rectangle_with_outward_normals() {
        let (outline, stable, camera, camera_T_table, _) = scene(0.002, -0.001, 0.3);
        let camera_T_part = camera_T_table * stable.table_T_part(0.002, -0.001, 0.3);
        let points = outline.outline(&camera, &camera_T_part, 2.0, false);
        let pixels: Vec<_> = points.iter().map(|p| p.pixel).collect();
        assert_eq!(outline.pixels(&camera, &camera_T_part, 2.0), pixels);
        let centre = camera.project(&(camera_T_part * Point3::origin())).unwrap();
        // 2 × (9 + 5) mm of perimeter at ≈ 7.1 px/mm, one sample per 2 px.
        assert!(
            (90..=110).contains(&points.len()),
            "{} samples",
            points.len()
        );
        for p in &points {
            let local = p.part;
            let on_side =
                (local.x.abs() - 4.5e-3).abs() < 1e-9 || (local.y.abs() - 2.5e-3).abs() < 1e-9;
            assert!(on_side, "{local} is not on the box's sides");
            assert!(
                p.normal.dot(&(p.pixel - centre)) > 0.0,
                "normal points inwards at {}",
                p.pixel
            );
        }
    }

    #[test]
    fn a_fit_is_trusted_from_nothing_at_the_minimum_support_to_fully_at_full_support() {
        let fit = |support| ContourFit {
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
            support,
        };
        assert_eq!(fit(0.3).quality(0.5), 0.0);
        assert_eq!(fit(0.5).quality(0.5), 0.0);
        assert!((fit(0.75).quality(0.5) - 0.25).abs() < 1e-12);
        assert_eq!(fit(1.0).quality(0.5), 1.0);
        let q: Vec<f64> = (50..=100)
            .map(|s| fit(f64::from(s) / 100.0).quality(0.5))
            .collect();
        assert!(q.windows(2).all(|w| w[0] < w[1]), "rises with the support");
    }

    /// How far `fit` is from the true (x, y, yaw) of a scene seen from 1.5 m: pixels, degrees.
    fn fit_error(fit: &ContourFit, truth: (f64, f64, f64), camera: &Camera) -> (f64, f64) {
        let px_per_m = camera.fx / 1.5;
        (
            (fit.x - truth.0).hypot(fit.y - truth.1) * px_per_m,
            (fit.yaw - truth.2).to_degrees().abs(),
        )
    }

    #[test]
    #[allow(non_snake_case)]
    fn a_box_is_aligned_to_a_hundredth_of_a_pixel_from_two_pixels_and_five_degrees_off() {
        let (x, y, yaw) = (0.002, -0.001, 0.3);
        let (outline, stable, camera, camera_T_table, patch) = scene(x, y, yaw);
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        let start = (x + 2e-4, y - 2e-4, yaw + 5f64.to_radians());
        let view = ContourView {
            outline: &outline,
            stable: &stable,
            camera: &camera,
            patch: &patch,
        };
        let fit = aligner.align(view, start).expect("the box is found");
        let (err_px, err_deg) = fit_error(&fit, (x, y, yaw), &camera);
        assert!(err_px < 0.01, "position off by {err_px:.4} px");
        assert!(err_deg < 0.01, "yaw off by {err_deg:.4}°");
        assert!(fit.support > 0.95, "support {}", fit.support);
        // A half-turn of a box is the same box; a quarter turn is not.
        let turned = aligner.align(view, (x, y, yaw + 1.4));
        assert!(turned.is_none_or(|f| f.support < 0.6), "{turned:?}");
    }

    #[test]
    #[allow(non_snake_case)]
    fn a_glare_beside_part_of_the_outline_pulls_the_finest_round_less() {
        // The box of `scene` with a glare as bright as the part, 1.5 px wide, along the half of
        // its +y side at +x: there the step lies 1.5 px outside the outline, and also turns the
        // fit. Equal weights (a Cauchy scale far above any residual) let those samples pull it
        // 0.39 px and 0.87°; the default scale (0.75 px) 0.25 px and 0.62°, a quarter-pixel
        // scale 0.07 px and 0.15° (measured).
        let (x, y, yaw) = (0.002, -0.001, 0.3);
        let shade = |d: f64, p: Point2<f64>| {
            let glare = d > -1.5 && p.y > 2.5e-3 && p.x > 0.0;
            if d >= 0.0 || glare { 200 } else { 40 }
        };
        let (outline, stable, camera, camera_T_table, patch) = scene_shaded(x, y, yaw, None, shade);
        let view = ContourView {
            outline: &outline,
            stable: &stable,
            camera: &camera,
            patch: &patch,
        };
        let start = (x + 1e-4, y - 1e-4, yaw + 1f64.to_radians());
        let fit = |final_cauchy_px: f64| {
            let config = ContourConfig {
                final_cauchy_px,
                ..ContourConfig::default()
            };
            let fit = ContourAligner::new(camera_T_table, config)
                .align(view, start)
                .expect("the box is found");
            fit_error(&fit, (x, y, yaw), &camera)
        };
        let (plain_px, plain_deg) = fit(1e9);
        let (weighted_px, weighted_deg) = fit(ContourConfig::default().final_cauchy_px);
        let (tight_px, tight_deg) = fit(0.25);
        assert!(
            plain_px > 0.3,
            "the glare pulls the plain fit by {plain_px:.3} px"
        );
        assert!(
            weighted_px < 0.7 * plain_px && weighted_deg < 0.75 * plain_deg,
            "the default weights gain too little: {plain_px:.3} → {weighted_px:.3} px, \
             {plain_deg:.3} → {weighted_deg:.3}°"
        );
        assert!(
            tight_px < 0.1 && tight_deg < 0.25,
            "a quarter-pixel scale leaves {tight_px:.3} px, {tight_deg:.3}°"
        );
    }

    #[test]
    #[allow(non_snake_case)]
    fn a_start_whose_ends_lie_beyond_the_coarse_reach_is_found_from_starts_around_it() {
        let (x, y, yaw) = (0.002, -0.001, 0.3);
        let (outline, stable, camera, camera_T_table, patch) = scene(x, y, yaw);
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        let view = ContourView {
            outline: &outline,
            stable: &stable,
            camera: &camera,
            patch: &patch,
        };
        // 1.2 mm along the box's 9 mm side (8.5 px; the coarse reach is 6 px) and 0.1 mm
        // across: the long sides are found, the ends are not.
        let (along, across) = (1.2e-3, 1e-4);
        let start = (
            x + along * yaw.cos() - across * yaw.sin(),
            y + along * yaw.sin() + across * yaw.cos(),
            yaw,
        );
        let screened = aligner
            .screen(view, start)
            .expect("the long sides are found");
        assert!(
            screened.support < aligner.config().ring_below,
            "support {}",
            screened.support
        );
        let around = aligner
            .screen_around(view, &screened)
            .expect("a start near the truth");
        assert!(around.support > 0.95, "support {}", around.support);
        let fit = aligner.finish(view, &around).expect("finished");
        let (err_px, err_deg) = fit_error(&fit, (x, y, yaw), &camera);
        assert!(err_px < 0.01, "position off by {err_px:.4} px");
        assert!(err_deg < 0.01, "yaw off by {err_deg:.4}°");
    }

    #[test]
    #[allow(non_snake_case)]
    fn a_silhouette_agrees_with_the_parts_mask_by_the_area_they_share() {
        let (x, y, yaw) = (0.0, 0.0, 0.0);
        let (outline, stable, camera, camera_T_table, patch) = scene(x, y, yaw);
        // The part's mask: the bright pixels of the frame (the box seen from above).
        let bright: Vec<(i64, i64)> = (0..patch.height)
            .flat_map(|i| (0..patch.width).map(move |j| (i, j)))
            .filter(|&(i, j)| patch.values[i * patch.width + j] > 0.5)
            .map(|(i, j)| {
                (
                    patch.origin[0] as i64 + j as i64,
                    patch.origin[1] as i64 + i as i64,
                )
            })
            .collect();
        let centre_x = camera
            .project(&(camera_T_table * Point3::new(x, y, 0.0)))
            .unwrap()
            .x;
        let owned = |patch: GreyPatch, right_hidden: bool| {
            patch.with_owners(|y, x, row| {
                for (k, owner) in row.iter_mut().enumerate() {
                    let px = x + k as i64;
                    if right_hidden && px as f64 > centre_x {
                        *owner = Owner::Other;
                    } else if bright.contains(&(px, y)) {
                        *owner = Owner::Me;
                    }
                }
            })
        };
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        let agreement = |patch: &GreyPatch, dx: f64| {
            let view = ContourView {
                outline: &outline,
                stable: &stable,
                camera: &camera,
                patch,
            };
            let fit = ContourFit {
                x: x + dx,
                y,
                yaw,
                support: 1.0,
            };
            aligner.mask_agreement(view, &fit)
        };
        assert_eq!(agreement(&patch, 0.0), None, "no mask, nothing to judge by");
        let mask = owned(scene(x, y, yaw).4, false);
        let at = agreement(&mask, 0.0).unwrap();
        assert!(at > 0.97, "at the truth: {at}");
        // 1 mm along the 9 × 5 mm box: they share 8 of the 10 mm their union spans.
        let off = agreement(&mask, 1e-3).unwrap();
        assert!((off - 0.8).abs() < 0.02, "1 mm off: {off}");
        // Where another part lies nothing counts: of the left half of the box, 3.5 of 4.5 mm.
        let half = owned(scene(x, y, yaw).4, true);
        let off = agreement(&half, 1e-3).unwrap();
        assert!(
            (off - 3.5 / 4.5).abs() < 0.02,
            "1 mm off, right half hidden: {off}"
        );
    }

    #[test]
    #[allow(non_snake_case)]
    fn samples_hidden_by_another_part_are_not_screened_or_counted() {
        // The lower third of the frame around the box is covered by another part (a flat grey),
        // which hides the box's lower side and the lower ends of its short sides.
        let (x, y, yaw) = (0.0, 0.0, 0.0);
        let (outline, stable, camera, camera_T_table, mut patch) = scene(x, y, yaw);
        let centre = camera
            .project(&(camera_T_table * stable.table_T_part(x, y, yaw) * Point3::origin()))
            .unwrap();
        let cut = centre.y + 10.0;
        for i in 0..patch.height {
            if patch.origin[1] + i as f64 > cut {
                patch.values[i * patch.width..(i + 1) * patch.width].fill(0.5);
            }
        }
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        let start = (x + 1e-4, y, yaw + 2f64.to_radians());
        let screened = |patch: &GreyPatch| {
            let view = ContourView {
                outline: &outline,
                stable: &stable,
                camera: &camera,
                patch,
            };
            aligner.screen(view, start).expect("the box is found")
        };
        let seen_all = screened(&patch);
        let patch = patch.with_owners(|y, _, row| {
            row.fill(if y as f64 > cut {
                Owner::Other
            } else {
                Owner::Nobody
            })
        });
        let seen_visible = screened(&patch);
        // Counted over all samples, the hidden ones miss; over those in sight, nearly all hit.
        assert!(seen_all.support < 0.8, "support {}", seen_all.support);
        assert!(
            seen_visible.support > 0.95,
            "support {}",
            seen_visible.support
        );
        let (err_px, err_deg) = fit_error(&seen_visible, (x, y, yaw), &camera);
        assert!(
            err_px < 0.05 && err_deg < 0.05,
            "{err_px:.3} px, {err_deg:.3}°"
        );
    }

    #[test]
    fn a_face_edge_inside_the_parts_mask_is_not_taken_for_its_outline() {
        // One row across a solid part's side: table (100) up to pixel 14, a bright bevel face
        // (170) to pixel 18, a dark top face (60) on. The sample sits at x = 19.5 with its
        // outward normal towards the table: the outline is 5 px out (x = 14.5), the edge
        // between the faces 1 px out and stronger (110 against 70 grey levels).
        let img = GrayImage::from_fn(40, 5, |x, _| {
            Luma([match x {
                0..15 => 100,
                15..19 => 170,
                _ => 60,
            }])
        });
        let patch = || {
            GreyPatch::cut(
                &DynamicImage::ImageLuma8(img.clone()),
                [0, 0],
                [0, 0, 40, 5],
            )
        };
        let (pixel, outward) = (Point2::new(19.5, 2.0), Vector2::new(-1.0, 0.0));
        let config = ContourConfig::default();
        let edge = |patch: &GreyPatch, read_mask| {
            let (offset, _) = patch
                .edge_along(
                    pixel,
                    outward,
                    6.0,
                    config.edge_share,
                    FinalEdge::Nearest,
                    read_mask,
                )
                .unwrap();
            offset
        };
        let mask = |patch: GreyPatch| {
            patch.with_owners(|_, x, row| {
                for (k, owner) in row.iter_mut().enumerate() {
                    if x + k as i64 >= 15 {
                        *owner = Owner::Me;
                    }
                }
            })
        };
        let read = mask(patch()).with_mask_outside(config.mask_outside_px);
        assert!(
            (edge(&patch(), true) - 1.0).abs() < 1e-9,
            "no mask: the nearer face edge"
        );
        assert!(
            (edge(&read, false) - 1.0).abs() < 1e-9,
            "the mask not read: the same"
        );
        assert!(
            (edge(&read, true) - 5.0).abs() < 1e-9,
            "the mask read: the outline"
        );
        // A mask that gives the part no pixel, or a depth of 0, says nothing.
        let nobody = patch()
            .with_owners(|_, _, row| row.fill(Owner::Nobody))
            .with_mask_outside(config.mask_outside_px);
        assert!((edge(&nobody, true) - 1.0).abs() < 1e-9);
        assert!((edge(&mask(patch()).with_mask_outside(0.0), true) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn the_outermost_rule_takes_a_weaker_outline_beyond_a_nearer_stronger_rim() {
        // One row across a shell's side: table (100) up to pixel 19, the shell's rim top (170),
        // a dark rim line (70) at pixel 22, the shell's inside (170). The outline sample sits at
        // x = 21.5, its outward normal towards the table: the outline is 2 px out (x = 19.5), the
        // rim line 0.5 px in, and its steps are stronger (100 against 70 grey levels).
        let img = GrayImage::from_fn(40, 5, |x, _| {
            Luma([match x {
                0..20 => 100,
                22 => 70,
                _ => 170,
            }])
        });
        let patch = GreyPatch::cut(&DynamicImage::ImageLuma8(img), [0, 0], [0, 0, 40, 5]);
        let (pixel, outward) = (Point2::new(21.5, 2.0), Vector2::new(-1.0, 0.0));
        let config = ContourConfig::default();
        let (nearest, _) = patch
            .edge_along(
                pixel,
                outward,
                3.0,
                config.edge_share,
                FinalEdge::Nearest,
                false,
            )
            .unwrap();
        let (outermost, contrast) = patch
            .edge_along(
                pixel,
                outward,
                3.0,
                config.outermost_share,
                FinalEdge::Outermost,
                false,
            )
            .unwrap();
        assert!((nearest + 0.5).abs() < 1e-9, "nearest rule: {nearest} px");
        assert!(
            (outermost - 2.0).abs() < 1e-9,
            "outermost rule: {outermost} px"
        );
        assert!((contrast - 70.0 / 255.0).abs() < 0.01, "{contrast}");
    }

    #[test]
    #[allow(non_snake_case)]
    fn a_shell_with_a_dark_rim_inside_its_outline_is_fitted_to_the_outline_by_either_rule() {
        // A light shell on a grey table (a step of 70 grey levels at the outline) with a dark
        // rim line 2.5–3.5 px inside it (steps of 100), started 1 px and 0.3° off.
        let (x, y, yaw) = (0.002, -0.001, 0.3);
        let shade = |d: f64, _| match d {
            d if d < 0.0 => 100,
            d if (2.5..3.5).contains(&d) => 70,
            _ => 170,
        };
        let (outline, stable, camera, camera_T_table, patch) = scene_shaded(x, y, yaw, None, shade);
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        let px_per_m = camera.fx / 1.5;
        let start = (x + 1.0 / px_per_m, y, yaw + 0.3f64.to_radians());
        for rule in [FinalEdge::Nearest, FinalEdge::Outermost] {
            let outline = outline.clone().with_final_edge(rule);
            let view = ContourView {
                outline: &outline,
                stable: &stable,
                camera: &camera,
                patch: &patch,
            };
            let fit = aligner.align(view, start).expect("the shell is found");
            let (err_px, err_deg) = fit_error(&fit, (x, y, yaw), &camera);
            assert!(err_px < 0.01, "{rule:?}: off by {err_px:.4} px");
            assert!(err_deg < 0.01, "{rule:?}: yaw off by {err_deg:.4}°");
        }
    }

    #[test]
    #[allow(non_snake_case)]
    fn a_window_through_the_part_outweighs_a_shadow_that_widens_its_outline() {
        // A light shell (170) on a grey table (120) with a 3 × 1.5 mm window through it, started
        // 1 px and 0.3° off. A dark shadow band (40) 2 px wide lies outside its +x wall: the
        // outermost rule takes the band's outer edge there, so the outer outline alone is
        // pulled towards +x. The window's edges are clean steps to the table seen through it.
        let (x, y, yaw) = (0.002, -0.001, 0.3);
        let window = Vector2::new(3e-3, 1.5e-3);
        let shade = |d: f64, p: Point2<f64>| {
            let in_window = p.x.abs() < window.x / 2.0 && p.y.abs() < window.y / 2.0;
            match d {
                d if d < -2.0 => 120,
                d if d < 0.0 => [120, 40][usize::from(p.x > 4.5e-3)],
                _ if in_window => 120,
                _ => 170,
            }
        };
        let (outline, stable, camera, camera_T_table, patch) =
            scene_shaded(x, y, yaw, Some(window), shade);
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        let px_per_m = camera.fx / 1.5;
        let start = (x + 1.0 / px_per_m, y, yaw + 0.3f64.to_radians());
        let fit = |weight: f64| {
            let outline = outline
                .clone()
                .with_final_edge(FinalEdge::Outermost)
                .with_hole_weight(weight);
            let view = ContourView {
                outline: &outline,
                stable: &stable,
                camera: &camera,
                patch: &patch,
            };
            let fit = aligner.align(view, start).expect("the shell is found");
            fit_error(&fit, (x, y, yaw), &camera)
        };
        // Weighed 20 times, the window's 9 mm of edge still share the fit with 28 mm of outer
        // outline, which keeps a twentieth or so of the band's pull (measured: 0.25 px and 0.15°
        // plain, 0.04 px and 0.02° weighed; 0.51 px and 0.34°, 0.09 px and 0.08° before the
        // finest round's Cauchy weights).
        let (plain_px, plain_deg) = fit(1.0);
        let (weighted_px, weighted_deg) = fit(20.0);
        assert!(
            plain_px > 0.2,
            "the shadow pulls the plain fit by {plain_px:.3} px"
        );
        assert!(
            weighted_px < 0.12,
            "off by {weighted_px:.3} px with the window weighed"
        );
        assert!(
            weighted_deg < 0.1,
            "yaw off by {weighted_deg:.3}° with the window weighed"
        );
        assert!(
            weighted_px < plain_px / 4.0 && weighted_deg < plain_deg / 4.0,
            "weighing the window gains less than fourfold: {plain_px:.3} → {weighted_px:.3} px, \
             {plain_deg:.3} → {weighted_deg:.3}°"
        );
    }
}
