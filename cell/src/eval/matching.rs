//! Matching detections to ground-truth instances: mask IoU, greedy assignment by score (each
//! ground-truth instance at most once, same part only), and which instances touch another.

use perception::learned::InstanceMask;

/// A mask from a full-image boolean raster, cropped to its bounding box (an empty mask when no
/// pixel is set).
pub fn mask_from_raster(bits: &[bool], width: u32, height: u32) -> InstanceMask {
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0u32, 0u32);
    for y in 0..height {
        let row = &bits[(y * width) as usize..((y + 1) * width) as usize];
        for (x, _) in row.iter().enumerate().filter(|(_, b)| **b) {
            let x = x as u32;
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 == u32::MAX {
        return InstanceMask {
            origin: [0, 0],
            width: 0,
            height: 0,
            bits: Vec::new(),
        };
    }
    let (w, h) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in y0..=y1 {
        let start = (y * width + x0) as usize;
        out.extend_from_slice(&bits[start..start + w as usize]);
    }
    InstanceMask {
        origin: [x0, y0],
        width: w,
        height: h,
        bits: out,
    }
}

/// Pixels set in both masks.
pub fn intersection(a: &InstanceMask, b: &InstanceMask) -> usize {
    let x0 = a.origin[0].max(b.origin[0]);
    let y0 = a.origin[1].max(b.origin[1]);
    let x1 = (a.origin[0] + a.width).min(b.origin[0] + b.width);
    let y1 = (a.origin[1] + a.height).min(b.origin[1] + b.height);
    let mut n = 0;
    for y in y0..y1 {
        for x in x0..x1 {
            if a.contains(x, y) && b.contains(x, y) {
                n += 1;
            }
        }
    }
    n
}

/// The mask among `masks` that overlaps `mask` most, by index, with that IoU (none without
/// any overlap): what a miss or a false positive is told apart by.
pub fn most_overlapping<'a>(
    masks: impl Iterator<Item = &'a InstanceMask>,
    mask: &InstanceMask,
) -> Option<(usize, f64)> {
    masks
        .map(|m| iou(m, mask))
        .enumerate()
        .filter(|(_, iou)| *iou > 0.0)
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// Intersection over union of two masks (0 when both are empty).
pub fn iou(a: &InstanceMask, b: &InstanceMask) -> f64 {
    let i = intersection(a, b);
    let u = a.area() + b.area() - i;
    if u == 0 { 0.0 } else { i as f64 / u as f64 }
}

/// Whether some pixel of `a` lies within `gap` pixels (Chebyshev distance) of a pixel of `b`:
/// the two instances touch (or overlap) in the image.
pub fn touches(a: &InstanceMask, b: &InstanceMask, gap: u32) -> bool {
    let g = i64::from(gap);
    let (ax0, ay0) = (i64::from(a.origin[0]), i64::from(a.origin[1]));
    let (bx0, by0) = (i64::from(b.origin[0]), i64::from(b.origin[1]));
    // Region of `a` that can be near `b`: b's box grown by the gap, clipped to a's box.
    let x0 = ax0.max(bx0 - g);
    let y0 = ay0.max(by0 - g);
    let x1 = (ax0 + i64::from(a.width)).min(bx0 + i64::from(b.width) + g);
    let y1 = (ay0 + i64::from(a.height)).min(by0 + i64::from(b.height) + g);
    for y in y0..y1 {
        for x in x0..x1 {
            if !a.contains(x as u32, y as u32) {
                continue;
            }
            for ny in (y - g).max(0)..=y + g {
                for nx in (x - g).max(0)..=x + g {
                    if b.contains(nx as u32, ny as u32) {
                        return true;
                    }
                }
            }
        }
    }
    false
}

/// For each instance, whether its mask touches another's within `gap` pixels.
pub fn touching_flags(masks: &[InstanceMask], gap: u32) -> Vec<bool> {
    let mut flags = vec![false; masks.len()];
    for i in 0..masks.len() {
        for j in i + 1..masks.len() {
            if (!flags[i] || !flags[j]) && touches(&masks[i], &masks[j], gap) {
                flags[i] = true;
                flags[j] = true;
            }
        }
    }
    flags
}

/// What matching needs of a detection.
#[derive(Debug, Clone, Copy)]
pub struct Candidate<'a> {
    /// Part name.
    pub part: &'a str,
    /// Detection score (higher first).
    pub score: f64,
    /// Its mask.
    pub mask: &'a InstanceMask,
}

/// What matching needs of a ground-truth instance.
#[derive(Debug, Clone, Copy)]
pub struct Truth<'a> {
    /// Part name.
    pub part: &'a str,
    /// Its visible mask.
    pub mask: &'a InstanceMask,
}

/// One match: detection index, ground-truth index, mask IoU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Match {
    /// Index into the detections.
    pub detection: usize,
    /// Index into the ground truth.
    pub truth: usize,
    /// Mask IoU of the pair.
    pub iou: f64,
}

/// Greedy matching as in COCO / BOP: detections in descending score order each take the
/// still-unmatched ground-truth instance of the same part with the highest mask IoU, if that IoU
/// reaches `min_iou`. Returns, per detection, its match (if any).
pub fn greedy_match(
    detections: &[Candidate<'_>],
    truths: &[Truth<'_>],
    min_iou: f64,
) -> Vec<Option<Match>> {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    // Stable sort: equal scores keep the detector's order.
    order.sort_by(|&a, &b| detections[b].score.total_cmp(&detections[a].score));
    let mut taken = vec![false; truths.len()];
    let mut out = vec![None; detections.len()];
    for d in order {
        let det = &detections[d];
        let mut best: Option<(usize, f64)> = None;
        for (t, truth) in truths.iter().enumerate() {
            if taken[t] || truth.part != det.part {
                continue;
            }
            let v = iou(det.mask, truth.mask);
            if v >= min_iou && best.is_none_or(|(_, b)| v > b) {
                best = Some((t, v));
            }
        }
        if let Some((t, v)) = best {
            taken[t] = true;
            out[d] = Some(Match {
                detection: d,
                truth: t,
                iou: v,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A filled rectangle mask `w × h` at (x, y).
    fn rect(x: u32, y: u32, w: u32, h: u32) -> InstanceMask {
        InstanceMask {
            origin: [x, y],
            width: w,
            height: h,
            bits: vec![true; (w * h) as usize],
        }
    }

    #[test]
    fn iou_of_overlapping_rectangles() {
        let a = rect(0, 0, 10, 10);
        let b = rect(5, 0, 10, 10);
        // 50 shared of 150 covered.
        assert_eq!(intersection(&a, &b), 50);
        assert!((iou(&a, &b) - 50.0 / 150.0).abs() < 1e-12);
        assert!((iou(&a, &a) - 1.0).abs() < 1e-12);
        assert_eq!(iou(&a, &rect(20, 20, 3, 3)), 0.0);
        let empty = mask_from_raster(&[false; 4], 2, 2);
        assert_eq!(iou(&empty, &empty), 0.0);
    }

    #[test]
    fn iou_respects_holes_in_the_box() {
        // A ring: 4 × 4 box with the inner 2 × 2 cleared (12 pixels).
        let mut ring = rect(0, 0, 4, 4);
        for (x, y) in [(1, 1), (2, 1), (1, 2), (2, 2)] {
            ring.bits[y * 4 + x] = false;
        }
        let inner = rect(1, 1, 2, 2);
        assert_eq!(intersection(&ring, &inner), 0);
        assert!((iou(&ring, &rect(0, 0, 4, 4)) - 12.0 / 16.0).abs() < 1e-12);
    }

    #[test]
    fn raster_is_cropped_to_its_box() {
        let (w, h) = (6u32, 5u32);
        let mut bits = vec![false; (w * h) as usize];
        for (x, y) in [(2, 1), (3, 1), (4, 3)] {
            bits[(y * w + x) as usize] = true;
        }
        let m = mask_from_raster(&bits, w, h);
        assert_eq!((m.origin, m.width, m.height), ([2, 1], 3, 3));
        assert_eq!(m.area(), 3);
        assert!(m.contains(2, 1) && m.contains(4, 3) && !m.contains(3, 2));
    }

    #[test]
    fn touching_needs_pixels_within_the_gap() {
        let a = rect(0, 0, 10, 10);
        // Adjacent: b starts right after a's last column.
        assert!(touches(&a, &rect(10, 0, 5, 5), 1));
        // Two empty columns between them: touch at gap 3, not at 2.
        let far = rect(12, 0, 5, 5);
        assert!(!touches(&a, &far, 2));
        assert!(touches(&a, &far, 3));
        assert!(touches(&far, &a, 3), "symmetric");
        // Diagonal neighbours touch at gap 1.
        assert!(touches(&a, &rect(10, 10, 2, 2), 1));
        // An L-shaped mask whose box overlaps b but whose pixels stay far from it does not.
        let mut l = rect(0, 0, 20, 20);
        for y in 2..20 {
            for x in 2..20 {
                l.bits[(y * 20 + x) as usize] = false;
            }
        }
        assert!(!touches(&l, &rect(10, 10, 5, 5), 2));
        let flags = touching_flags(&[a.clone(), rect(10, 0, 5, 5), rect(50, 50, 3, 3)], 1);
        assert_eq!(flags, vec![true, true, false]);
    }

    #[test]
    fn greedy_matching_by_score_each_truth_once_same_part() {
        let t0 = rect(0, 0, 10, 10);
        let t1 = rect(30, 0, 10, 10);
        let truths = [
            Truth {
                part: "a",
                mask: &t0,
            },
            Truth {
                part: "b",
                mask: &t1,
            },
        ];
        let d_low = rect(1, 0, 10, 10); // IoU 90/110 with t0
        let d_high = rect(2, 0, 10, 10); // IoU 80/120 with t0
        let d_wrong_part = rect(30, 0, 10, 10); // perfect overlap with t1 but labelled "a"
        let d_poor = rect(6, 0, 10, 10); // IoU 40/160 < 0.5
        let dets = [
            Candidate {
                part: "a",
                score: 0.5,
                mask: &d_low,
            },
            Candidate {
                part: "a",
                score: 0.9,
                mask: &d_high,
            },
            Candidate {
                part: "a",
                score: 0.99,
                mask: &d_wrong_part,
            },
            Candidate {
                part: "a",
                score: 0.1,
                mask: &d_poor,
            },
        ];
        let m = greedy_match(&dets, &truths, 0.5);
        // The higher-scored detection takes t0 even though the other overlaps it better.
        assert_eq!(m[1].map(|m| m.truth), Some(0));
        assert!((m[1].unwrap().iou - 80.0 / 120.0).abs() < 1e-12);
        assert_eq!(m[0], None, "t0 is taken: a duplicate is a false positive");
        assert_eq!(m[2], None, "wrong part never matches");
        assert_eq!(m[3], None, "below the IoU threshold");
    }
}
