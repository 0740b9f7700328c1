//! From the segmenter's cells to part instances: every foreground cell votes for its instance
//! centre (cell centre + predicted offset) on its class's vote map; peaks at least
//! `min_separation_px` from a stronger peak of the same class, and `cross_separation_px` from one
//! of another class, are the instances (so touching parts with distinct centres separate, and a
//! part half hidden under another part keeps its own instance when its visible cells carry its
//! class); each foreground cell joins the nearest peak of its class within `assign_radius_px`,
//! or else the nearest peak of any class (a stray mislabelled cell joins the part it lies on);
//! an instance's class is its peak's and its score the mean probability of that class. The
//! settings are in pixels at a reference image scale; each frame scales them by its own (a part
//! seen from 1.4 m is 1.3 times as large as from 1.8 m).

use super::detection::InstanceMask;
use super::models::SEGMENTER_STRIDE;
use super::net_view::NetView;
use super::segmenter::SegmentMap;

/// Grouping settings, in pixels at the image scale `reference_px_per_mm`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InstanceConfig {
    /// The image scale the pixel settings are for: pixels per mm on the table.
    pub reference_px_per_mm: f64,
    /// Two instance centres of one class are at least this far apart, pixels (parts are
    /// 60–80 px across; a large part's far cells, whose offsets fall short, can vote for a
    /// second centre more than 24 px from the first).
    pub min_separation_px: f64,
    /// Two instance centres of different classes are at least this far apart, pixels: closer,
    /// the weaker peak is the stronger one's part with some cells mislabelled.
    pub cross_separation_px: f64,
    /// The smallest score of an instance whose peak lies closer than `min_separation_px` to a
    /// stronger peak of another class.
    pub contested_min_score: f64,
    /// A cell joins a centre when its vote lands within this distance, pixels.
    pub assign_radius_px: f64,
    /// Radius of the mean shift that refines a peak to the mean of the votes near it, pixels.
    pub refine_radius_px: f64,
    /// Votes (cells) a peak needs, summed over its 3 × 3 cell neighbourhood.
    pub min_peak_votes: f64,
    /// Instances with fewer cells are dropped (each cell is 4 × 4 pixels).
    pub min_cells: usize,
}

impl Default for InstanceConfig {
    fn default() -> Self {
        Self {
            // The seed's camera (fx 10 704 px) 1.5 m above the table.
            reference_px_per_mm: 7.14,
            min_separation_px: 30.0,
            cross_separation_px: 10.0,
            contested_min_score: 0.75,
            assign_radius_px: 24.0,
            refine_radius_px: 8.0,
            min_peak_votes: 8.0,
            min_cells: 40,
        }
    }
}

impl InstanceConfig {
    /// The same settings for an image of `px_per_mm` on the table: distances scaled by the
    /// ratio to the reference, cell counts by its square.
    pub fn at_scale(&self, px_per_mm: f64) -> Self {
        let k = px_per_mm / self.reference_px_per_mm;
        Self {
            reference_px_per_mm: px_per_mm,
            min_separation_px: self.min_separation_px * k,
            cross_separation_px: self.cross_separation_px * k,
            assign_radius_px: self.assign_radius_px * k,
            refine_radius_px: self.refine_radius_px * k,
            min_peak_votes: self.min_peak_votes * k * k,
            min_cells: (self.min_cells as f64 * k * k).round() as usize,
            ..*self
        }
    }
}

/// One instance found in a segment map (coordinates in pixels of the segmented region).
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    /// Part index (class − 1).
    pub part: usize,
    /// Mean probability of the class over the instance's cells.
    pub score: f64,
    /// Voted centre, region pixels.
    pub centre: [f64; 2],
    /// Row-major indices of its cells.
    pub cells: Vec<u32>,
}

impl Instance {
    /// The instance's mask in sensor pixels (each cell covers 4 × 4 net pixels, which `view`
    /// maps to the sensor), clipped to the region of `valid` `[width, height]` sensor pixels.
    pub fn mask(&self, map_width: usize, valid: [usize; 2], view: &NetView) -> InstanceMask {
        let empty = || InstanceMask {
            origin: view.region,
            width: 0,
            height: 0,
            bits: Vec::new(),
        };
        if self.cells.is_empty() {
            return empty();
        }
        let (mut j0, mut i0, mut j1, mut i1) = (usize::MAX, usize::MAX, 0, 0);
        for &c in &self.cells {
            let (i, j) = (c as usize / map_width, c as usize % map_width);
            (j0, i0, j1, i1) = (j0.min(j), i0.min(i), j1.max(j + 1), i1.max(i + 1));
        }
        let clip = |a: usize, [lo, hi]: [i64; 2]| [lo.max(0), hi.min(valid[a] as i64)];
        let [x0, x1] = clip(0, view.cells_to_pixels(0, [j0, j1]));
        let [y0, y1] = clip(1, view.cells_to_pixels(1, [i0, i1]));
        if x1 <= x0 || y1 <= y0 {
            return empty();
        }
        // The instance's cells over its bounding box of cells.
        let cw = j1 - j0;
        let mut mine = vec![false; cw * (i1 - i0)];
        for &c in &self.cells {
            let (i, j) = (c as usize / map_width, c as usize % map_width);
            mine[(i - i0) * cw + (j - j0)] = true;
        }
        let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
        let mut bits = vec![false; w * h];
        for (y, row) in (y0..y1).zip(bits.chunks_mut(w)) {
            let i = view.cell_of(1, y) - i0 as i64;
            if !(0..(i1 - i0) as i64).contains(&i) {
                continue;
            }
            for (x, bit) in (x0..x1).zip(row.iter_mut()) {
                let j = view.cell_of(0, x) - j0 as i64;
                *bit = (0..cw as i64).contains(&j) && mine[i as usize * cw + j as usize];
            }
        }
        InstanceMask {
            origin: [view.region[0] + x0 as u32, view.region[1] + y0 as u32],
            width: w as u32,
            height: h as u32,
            bits,
        }
    }
}

/// Shared border, in cells, from which two instances count as one part split in two.
const MIN_SHARED_BORDER: usize = 3;

/// Joins instances of one part that share a border of at least [`MIN_SHARED_BORDER`] cells and
/// together hold no more than `max_cells[part]` cells, the pair with the longest border first,
/// until none is left: a long part lying on its side is sometimes seen as two instances, its far
/// cells' offsets falling short of its centre. The joined instance's centre and score are the
/// cell-weighted means of the two. `map_width` × `map_height` is the segment map's size.
pub fn join_split(
    instances: &mut Vec<Instance>,
    map_width: usize,
    map_height: usize,
    max_cells: &[usize],
) {
    let mut owner = vec![usize::MAX; map_width * map_height];
    loop {
        owner.fill(usize::MAX);
        for (k, inst) in instances.iter().enumerate() {
            for &c in &inst.cells {
                owner[c as usize] = k;
            }
        }
        let mut best: Option<(usize, usize, usize)> = None;
        for (i, a) in instances.iter().enumerate() {
            let mut borders: Vec<(usize, usize)> = Vec::new();
            for &c in &a.cells {
                let c = c as usize;
                let (y, x) = (c / map_width, c % map_width);
                let neighbours = [
                    (x > 0).then(|| c - 1),
                    (x + 1 < map_width).then(|| c + 1),
                    (y > 0).then(|| c - map_width),
                    (y + 1 < map_height).then(|| c + map_width),
                ];
                for j in neighbours.into_iter().flatten().map(|n| owner[n]) {
                    if j == usize::MAX || j <= i || instances[j].part != a.part {
                        continue;
                    }
                    match borders.iter_mut().find(|(o, _)| *o == j) {
                        Some((_, n)) => *n += 1,
                        None => borders.push((j, 1)),
                    }
                }
            }
            let limit = max_cells.get(a.part).copied().unwrap_or(0);
            for (j, border) in borders {
                let fits = a.cells.len() + instances[j].cells.len() <= limit;
                if border >= MIN_SHARED_BORDER && fits && best.is_none_or(|(_, _, b)| border > b) {
                    best = Some((i, j, border));
                }
            }
        }
        let Some((i, j, _)) = best else {
            return;
        };
        let b = instances.remove(j);
        let a = &mut instances[i];
        let (na, nb) = (a.cells.len() as f64, b.cells.len() as f64);
        let mean = |x: f64, y: f64| (x * na + y * nb) / (na + nb);
        a.score = mean(a.score, b.score);
        a.centre = [
            mean(a.centre[0], b.centre[0]),
            mean(a.centre[1], b.centre[1]),
        ];
        a.cells.extend(b.cells);
    }
}

/// Groups cells into instances, reusing its buffers between frames.
#[derive(Debug, Clone, Default)]
pub struct InstanceGrouper {
    config: InstanceConfig,
    votes: Vec<[f32; 2]>,
    voters: Vec<u32>,
    accumulator: Vec<f32>,
    owner: Vec<u32>,
}

impl InstanceGrouper {
    /// A grouper with these settings.
    pub fn new(config: InstanceConfig) -> Self {
        Self {
            config,
            ..Self::default()
        }
    }

    /// Its settings.
    pub fn config(&self) -> &InstanceConfig {
        &self.config
    }

    /// The instances of `map`, an image of `px_per_mm` on the table, strongest peak first.
    pub fn group(&mut self, map: &SegmentMap, px_per_mm: f64) -> Vec<Instance> {
        let config = self.config.at_scale(px_per_mm);
        let (w, h) = (map.width, map.height);
        let plane = w * h;
        let parts = map.classes.saturating_sub(1);
        let s = SEGMENTER_STRIDE as f32;
        // 1. Votes of the foreground cells, splatted bilinearly onto their class's cell grid.
        self.votes.clear();
        self.voters.clear();
        self.accumulator.clear();
        self.accumulator.resize(parts * plane, 0.0);
        for c in 0..plane {
            let class = usize::from(map.class[c]);
            if class == 0 || class > parts {
                continue;
            }
            let (i, j) = (c / w, c % w);
            let vx = s * j as f32 + 1.5 + map.offsets[c];
            let vy = s * i as f32 + 1.5 + map.offsets[plane + c];
            if !(vx.is_finite() && vy.is_finite()) {
                continue;
            }
            self.votes.push([vx, vy]);
            self.voters.push(c as u32);
            let acc = &mut self.accumulator[(class - 1) * plane..class * plane];
            let (gx, gy) = ((vx - 1.5) / s, (vy - 1.5) / s);
            let (fx, fy) = (gx.floor(), gy.floor());
            let (ax, ay) = (gx - fx, gy - fy);
            for (dy, wy) in [(0, 1.0 - ay), (1, ay)] {
                for (dx, wx) in [(0, 1.0 - ax), (1, ax)] {
                    let (x, y) = (fx as i64 + dx, fy as i64 + dy);
                    if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h {
                        acc[y as usize * w + x as usize] += wx * wy;
                    }
                }
            }
        }
        // 2. Peaks: local maxima of each class's 3 × 3 vote sums, strongest first, kept when far
        //    enough from every stronger peak.
        let sum3 = |acc: &[f32], i: usize, j: usize| {
            let mut t = 0.0;
            for y in i.saturating_sub(1)..(i + 2).min(h) {
                for x in j.saturating_sub(1)..(j + 2).min(w) {
                    t += acc[y * w + x];
                }
            }
            t
        };
        let mut candidates = Vec::new();
        for k in 0..parts {
            let acc = &self.accumulator[k * plane..(k + 1) * plane];
            for i in 0..h {
                for j in 0..w {
                    if acc[i * w + j] <= 0.0 {
                        continue;
                    }
                    let v = sum3(acc, i, j);
                    if f64::from(v) < config.min_peak_votes {
                        continue;
                    }
                    let mut is_max = true;
                    'n: for y in i.saturating_sub(1)..(i + 2).min(h) {
                        for x in j.saturating_sub(1)..(j + 2).min(w) {
                            let u = sum3(acc, y, x);
                            if u > v || (u == v && (y * w + x) < (i * w + j)) {
                                is_max = false;
                                break 'n;
                            }
                        }
                    }
                    if is_max {
                        candidates.push((v, k + 1, [s * j as f32 + 1.5, s * i as f32 + 1.5]));
                    }
                }
            }
        }
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
        let sep2 = (config.min_separation_px * config.min_separation_px) as f32;
        let cross2 = (config.cross_separation_px * config.cross_separation_px) as f32;
        let mut peaks: Vec<(usize, [f32; 2])> = Vec::new();
        for (_, class, p) in candidates {
            let p = self.mean_shift(map, class, p, config.refine_radius_px);
            let apart = |(k, q): &(usize, [f32; 2])| {
                dist2(*q, p) >= if *k == class { sep2 } else { cross2 }
            };
            if peaks.iter().all(apart) {
                peaks.push((class, p));
            }
        }
        // 3. Each voting cell joins the nearest peak of its class within the radius, or else the
        //    nearest of any class.
        self.assign(map, &peaks, config.assign_radius_px);
        // 4. A peak closer than one class's separation to a stronger peak of another class stays
        //    only when its cells are confident of its class: otherwise it is a mislabelled patch
        //    of the stronger peak's part, whose cells then join it.
        let mut members = self.members(peaks.len());
        let keep: Vec<bool> = peaks
            .iter()
            .enumerate()
            .map(|(n, &(class, p))| {
                let contested = peaks[..n]
                    .iter()
                    .any(|(k, q)| *k != class && dist2(*q, p) < sep2);
                !contested
                    || mean_probability(map, class, &members[n]) >= config.contested_min_score
            })
            .collect();
        if keep.contains(&false) {
            peaks = peaks
                .into_iter()
                .zip(keep)
                .filter(|(_, k)| *k)
                .map(|(p, _)| p)
                .collect();
            self.assign(map, &peaks, config.assign_radius_px);
            members = self.members(peaks.len());
        }
        // 5. Class by the peak, score by mean probability, centre by the refined peak.
        peaks
            .iter()
            .zip(members)
            .filter(|(_, cells)| cells.len() >= config.min_cells.max(1))
            .map(|(&(class, peak), cells)| Instance {
                part: class - 1,
                score: mean_probability(map, class, &cells),
                centre: [f64::from(peak[0]), f64::from(peak[1])],
                cells,
            })
            .collect()
    }

    /// Sets each vote's owner: the nearest peak of its cell's class within `radius` pixels, or
    /// else the nearest peak of any class within it.
    fn assign(&mut self, map: &SegmentMap, peaks: &[(usize, [f32; 2])], radius: f64) {
        let r2 = (radius * radius) as f32;
        self.owner.clear();
        self.owner.resize(self.votes.len(), u32::MAX);
        for (k, (v, &c)) in self.votes.iter().zip(&self.voters).enumerate() {
            let class = usize::from(map.class[c as usize]);
            let nearest = |same: bool| {
                peaks
                    .iter()
                    .enumerate()
                    .filter(|(_, (pc, _))| !same || *pc == class)
                    .map(|(n, (_, p))| (n, dist2(*p, *v)))
                    .filter(|(_, d)| *d <= r2)
                    .min_by(|a, b| a.1.total_cmp(&b.1))
            };
            if let Some((n, _)) = nearest(true).or_else(|| nearest(false)) {
                self.owner[k] = n as u32;
            }
        }
    }

    /// The cells each of `peaks` peaks owns, in one pass over the votes.
    fn members(&self, peaks: usize) -> Vec<Vec<u32>> {
        let mut members = vec![Vec::new(); peaks];
        for (&o, &c) in self.owner.iter().zip(&self.voters) {
            if let Some(cells) = members.get_mut(o as usize) {
                cells.push(c);
            }
        }
        members
    }

    /// Moves `p` to the mean of the votes of `class` within `radius` pixels, a few times.
    fn mean_shift(&self, map: &SegmentMap, class: usize, mut p: [f32; 2], radius: f64) -> [f32; 2] {
        let r2 = (radius * radius) as f32;
        for _ in 0..3 {
            let (mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0usize);
            for (v, &c) in self.votes.iter().zip(&self.voters) {
                if usize::from(map.class[c as usize]) == class && dist2(*v, p) <= r2 {
                    sx += f64::from(v[0]);
                    sy += f64::from(v[1]);
                    n += 1;
                }
            }
            if n == 0 {
                break;
            }
            p = [(sx / n as f64) as f32, (sy / n as f64) as f32];
        }
        p
    }
}

/// The mean probability of `class` over `cells` (0 for none).
fn mean_probability(map: &SegmentMap, class: usize, cells: &[u32]) -> f64 {
    let plane = map.width * map.height;
    let sum: f64 = cells
        .iter()
        .map(|&c| f64::from(map.probs[class * plane + c as usize]))
        .sum();
    if cells.is_empty() {
        0.0
    } else {
        sum / cells.len() as f64
    }
}

fn dist2(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default settings' own image scale.
    const REFERENCE: f64 = 7.14;

    /// An instance of `part` over the cells of columns `cols` × rows `rows` of a 10-wide map.
    fn block(part: usize, cols: std::ops::Range<u32>, rows: std::ops::Range<u32>) -> Instance {
        let cells: Vec<u32> = rows
            .flat_map(|i| cols.clone().map(move |j| i * 10 + j))
            .collect();
        Instance {
            part,
            score: 0.5 + 0.1 * part as f64,
            centre: [0.0, 0.0],
            cells,
        }
    }

    #[test]
    fn halves_of_one_part_are_joined_and_neighbours_are_not() {
        // Part 0 split into a 3 × 4 and a 2 × 4 block sharing a 4-cell border; a part-1 block
        // borders it too; a part-0 block one column away shares no border.
        let mut left = block(0, 0..3, 0..4);
        left.centre = [6.0, 8.0];
        let mut right = block(0, 3..5, 0..4);
        right.centre = [16.0, 8.0];
        right.score = 0.8;
        let other = block(1, 5..7, 0..4);
        let apart = block(0, 8..10, 0..4);
        let all = vec![left, right, other, apart];
        let mut joined = all.clone();
        join_split(&mut joined, 10, 4, &[20, 20]);
        assert_eq!(joined.len(), 3);
        let j = &joined[0];
        assert_eq!((j.part, j.cells.len()), (0, 20));
        // Cell-weighted means: 12 and 8 cells.
        assert!((j.centre[0] - 10.0).abs() < 1e-12 && (j.centre[1] - 8.0).abs() < 1e-12);
        assert!((j.score - (0.5 * 12.0 + 0.8 * 8.0) / 20.0).abs() < 1e-12);
        assert_eq!((joined[1].part, joined[2].cells.len()), (1, 8));
        // Together larger than the part may be: both kept.
        let mut kept = all.clone();
        join_split(&mut kept, 10, 4, &[19, 19]);
        assert_eq!(kept, all);
        // A border of two cells is a touch, not a split.
        let mut touching = vec![block(0, 0..3, 0..2), block(0, 3..5, 1..3)];
        join_split(&mut touching, 10, 4, &[20, 20]);
        assert_eq!(touching.len(), 2);
    }

    /// A map of two touching discs (classes 1 and 3) whose cells point at their centres with
    /// small deterministic offset noise, plus a 3-cell speck of class 2 far away.
    fn two_touching_discs(centres: [[f64; 2]; 2]) -> (SegmentMap, [[f64; 2]; 2]) {
        let (w, h) = (40, 30);
        let plane = w * h;
        let mut map = SegmentMap {
            width: w,
            height: h,
            classes: 4,
            class: vec![0; plane],
            probs: vec![0.0; 4 * plane],
            offsets: vec![0.0; 2 * plane],
        };
        for c in 0..plane {
            map.probs[c] = 1.0;
        }
        for i in 0..h {
            for j in 0..w {
                let c = i * w + j;
                let (x, y) = (4.0 * j as f64 + 1.5, 4.0 * i as f64 + 1.5);
                let d: Vec<f64> = centres
                    .iter()
                    .map(|q| ((x - q[0]).powi(2) + (y - q[1]).powi(2)).sqrt())
                    .collect();
                let k = if d[0] <= d[1] { 0 } else { 1 };
                if d[k] > 24.0 {
                    continue;
                }
                let class = [1u8, 3][k];
                map.class[c] = class;
                map.probs[c] = 0.1;
                map.probs[class as usize * plane + c] = 0.8;
                map.probs[2 * plane + c] = 0.1;
                let noise = 1.5 * ((c * 7919) as f64).sin();
                map.offsets[c] = (centres[k][0] - x + noise) as f32;
                map.offsets[plane + c] = (centres[k][1] - y - noise) as f32;
            }
        }
        // One mislabelled cell inside disc 0 (majority must win) and a far speck.
        let inside = 15 * w + 12;
        assert_eq!(map.class[inside], 1);
        map.class[inside] = 2;
        for c in [25 * w + 35, 25 * w + 36, 26 * w + 35] {
            map.class[c] = 2;
            map.probs[2 * plane + c] = 0.9;
        }
        (map, centres)
    }

    #[test]
    fn touching_instances_separate_by_their_voted_centres() {
        // 46.9 px apart: the discs (r = 24) touch; 28.2 px apart: they overlap (each keeps the
        // cells nearer its own centre).
        for centres in [[[50.3, 61.7], [97.1, 58.2]], [[50.3, 61.7], [78.1, 57.2]]] {
            separate(centres);
        }
    }

    fn separate(centres: [[f64; 2]; 2]) {
        let (map, centres) = two_touching_discs(centres);
        let instances = InstanceGrouper::new(InstanceConfig::default()).group(&map, REFERENCE);
        assert_eq!(instances.len(), 2, "{instances:?}");
        let mut found: Vec<&Instance> = instances.iter().collect();
        found.sort_by(|a, b| a.centre[0].total_cmp(&b.centre[0]));
        for (inst, (centre, part)) in found.iter().zip(centres.iter().zip([0, 2])) {
            assert_eq!(inst.part, part);
            let err = ((inst.centre[0] - centre[0]).powi(2) + (inst.centre[1] - centre[1]).powi(2))
                .sqrt();
            assert!(err < 1.0, "centre {:?} vs {centre:?}", inst.centre);
            assert!((inst.score - 0.8).abs() < 0.01, "{}", inst.score);
            // Every cell of the instance is on its own disc: none leaked across the contact.
            for &c in &inst.cells {
                let (i, j) = (c as usize / map.width, c as usize % map.width);
                let (x, y) = (4.0 * j as f64 + 1.5, 4.0 * i as f64 + 1.5);
                assert!(((x - centre[0]).powi(2) + (y - centre[1]).powi(2)).sqrt() <= 24.0);
            }
        }
        // Disc cells: both discs are fully assigned (the speck is too small to be an instance).
        let assigned: usize = instances.iter().map(|i| i.cells.len()).sum();
        let fg = map.class.iter().filter(|&&c| c != 0).count();
        assert_eq!(assigned, fg - 3);
    }

    #[test]
    fn a_part_half_under_another_part_keeps_its_instance() {
        // 16 px apart, closer than one class's separation: a top shell lying over a main shell.
        separate([[50.3, 61.7], [66.1, 59.2]]);
    }

    #[test]
    fn a_part_with_a_mislabelled_patch_stays_one_instance() {
        // Disc 1 (class 3) relabels the cells right of x = 102 (over a third) as class 2: their
        // votes peak on the disc's own centre, too close to the stronger peak to be a part.
        let (mut map, centres) = two_touching_discs([[30.3, 61.7], [100.1, 58.2]]);
        let (w, plane) = (map.width, map.width * map.height);
        let mut relabelled = 0;
        for c in 0..plane {
            if map.class[c] == 3 && 4.0 * (c % w) as f64 + 1.5 > 102.0 {
                map.class[c] = 2;
                relabelled += 1;
            }
        }
        assert!(
            relabelled > 40,
            "{relabelled} cells: enough for an instance of their own"
        );
        the_right_disc_is_one_instance(&map, centres[1]);
    }

    #[test]
    fn an_unsure_patch_voting_beside_its_part_joins_it() {
        // Disc 1 (class 3) relabels the cells right of x = 102 as class 2 with probability 0.55,
        // and their votes land 15 px right of the disc's centre: a peak of its own, contested by
        // the disc's and not sure of its class, so its cells join the disc.
        let (mut map, centres) = two_touching_discs([[30.3, 61.7], [100.1, 58.2]]);
        let (w, plane) = (map.width, map.width * map.height);
        for c in 0..plane {
            if map.class[c] == 3 && 4.0 * (c % w) as f64 + 1.5 > 102.0 {
                map.class[c] = 2;
                map.probs[2 * plane + c] = 0.55;
                map.probs[3 * plane + c] = 0.35;
                map.offsets[c] += 15.0;
            }
        }
        the_right_disc_is_one_instance(&map, centres[1]);
        // Sure of its class, the same patch is a part of its own (one under the disc).
        for c in 0..plane {
            if map.class[c] == 2 && map.probs[2 * plane + c] == 0.55 {
                map.probs[2 * plane + c] = 0.85;
            }
        }
        let instances = InstanceGrouper::new(InstanceConfig::default()).group(&map, REFERENCE);
        assert_eq!(instances.len(), 3, "{instances:?}");
    }

    /// Groups `map` (two discs, the right one centred at `centre`) and checks that the right
    /// disc is one instance of its class (2), centred on it, with every cell of the disc.
    fn the_right_disc_is_one_instance(map: &SegmentMap, centre: [f64; 2]) {
        let instances = InstanceGrouper::new(InstanceConfig::default()).group(map, REFERENCE);
        assert_eq!(instances.len(), 2, "{instances:?}");
        let right = instances
            .iter()
            .max_by(|a, b| a.centre[0].total_cmp(&b.centre[0]))
            .expect("two instances");
        assert_eq!(right.part, 2, "the disc keeps its class");
        let err = (right.centre[0] - centre[0]).hypot(right.centre[1] - centre[1]);
        assert!(err < 1.0, "centre {:?} vs {centre:?}", right.centre);
        let w = map.width;
        let disc = (0..w * map.height).filter(|&c| {
            let (x, y) = (4.0 * (c % w) as f64 + 1.5, 4.0 * (c / w) as f64 + 1.5);
            map.class[c] != 0 && (x - centre[0]).hypot(y - centre[1]) <= 24.0
        });
        assert_eq!(
            right.cells.len(),
            disc.count(),
            "every cell of the disc, relabelled ones too"
        );
    }

    #[test]
    fn the_settings_scale_with_the_image() {
        let twice = InstanceConfig::default().at_scale(2.0 * REFERENCE);
        assert_eq!(
            (twice.min_separation_px, twice.assign_radius_px),
            (60.0, 48.0)
        );
        assert_eq!((twice.min_peak_votes, twice.min_cells), (32.0, 160));
        // Two discs of one class 36 px apart are two parts at the reference scale; at 1.5
        // times it, one part's separation is 45 px, so they are one.
        let (mut map, _) = two_touching_discs([[50.3, 61.7], [86.3, 59.2]]);
        let plane = map.width * map.height;
        for c in 0..plane {
            if map.class[c] == 3 {
                map.class[c] = 1;
                (map.probs[plane + c], map.probs[3 * plane + c]) = (0.8, 0.1);
            }
        }
        let mut grouper = InstanceGrouper::new(InstanceConfig::default());
        assert_eq!(grouper.group(&map, REFERENCE).len(), 2);
        assert_eq!(grouper.group(&map, 1.5 * REFERENCE).len(), 1);
    }

    #[test]
    fn masks_cover_four_by_four_pixels_per_cell_clipped_to_the_region() {
        let inst = Instance {
            part: 0,
            score: 1.0,
            centre: [0.0, 0.0],
            cells: vec![0, 1, 3 + 2],
        };
        // Map 3 cells wide; region 10 × 7 pixels: cell (1, 2) is clipped to 2 × 3 pixels.
        let m = inst.mask(3, [10, 7], &NetView::new([100, 200], [10, 7], 7.0, None));
        assert_eq!((m.origin, m.width, m.height), ([100, 200], 10, 7));
        assert_eq!(m.area(), 32 + 2 * 3);
        assert!(m.contains(100, 200) && m.contains(107, 203) && m.contains(109, 206));
        assert!(!m.contains(100, 204) && !m.contains(110, 206));
    }

    #[test]
    fn a_frame_shown_at_half_scale_gives_masks_of_eight_by_eight_pixels_per_cell() {
        let inst = Instance {
            part: 0,
            score: 1.0,
            centre: [0.0, 0.0],
            cells: vec![1, 3 + 2],
        };
        // 40 × 40 sensor pixels seen as 20 × 20 net pixels: cell (0, 1) is sensor pixels
        // 8..16 × 0..8, cell (1, 2) 16..24 × 8..16.
        let view = NetView::new([50, 60], [40, 40], 10.0, Some(5.0));
        let m = inst.mask(3, [40, 40], &view);
        assert_eq!((m.origin, m.width, m.height), ([58, 60], 16, 16));
        assert_eq!(m.area(), 2 * 64);
        assert!(m.contains(58, 60) && m.contains(65, 67) && m.contains(73, 75));
        assert!(!m.contains(66, 60) && !m.contains(58, 68));
    }
}
