//! The points of a board an operator touches with a pointer tool: the outer corner of the black
//! border of the tag nearest each corner of the plate, then of the tag nearest the middle of each
//! edge. A sharp black-on-white corner is what a pointer tip finds precisely by eye, and the board
//! already prints it, so no extra mark is needed on the plate (the SVG writer and the renderer
//! print these corners as part of the tags).
//!
//! Three marks fit a pose; four or more also place each touch from the others, so a wrong one is
//! found. All marks lie in the board's plane, so a touch that stops short of the surface (an
//! error along the normal) is only attributable to one mark with five or more: among four
//! coplanar points, lifting one is the same misfit as lifting the opposite one.

use nalgebra::Point3;

use super::Board;

/// One point of the board to touch.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchMark {
    /// Where it is, in words an operator follows ("top-left corner of tag 0 …").
    pub name: String,
    /// The tag whose border corner it is.
    pub tag: u32,
    /// Which corner of that tag, in [`Board::corners`]' order (0 bottom-left, 1 bottom-right,
    /// 2 top-right, 3 top-left, seen upright).
    pub corner: usize,
    /// The point on the board's top face, board frame, metres.
    pub point: Point3<f64>,
}

/// Names of the corners in [`Board::corners`]' order, seen from above with the tags upright.
const CORNER_NAMES: [&str; 4] = ["bottom-left", "bottom-right", "top-right", "top-left"];

/// The plate points the marks are nearest to, in the order listed, as fractions of the half plate
/// along (x, y): the corners clockwise from the top-left (where tag ids start), then the middles
/// of the top, right, bottom and left edges.
const PLATE_POINTS: [(f64, f64); 8] = [
    (-1.0, 1.0),
    (1.0, 1.0),
    (1.0, -1.0),
    (-1.0, -1.0),
    (0.0, 1.0),
    (1.0, 0.0),
    (0.0, -1.0),
    (-1.0, 0.0),
];

impl Board {
    /// The points to touch: for each corner of the plate, then for the middle of each edge, the
    /// printed tag border corner nearest to it (on a small board one tag can give several marks,
    /// at different corners). Without repeats; at least three and never all on one line, since
    /// every board has a tag with four corners. The seed's board has eight.
    pub fn touch_marks(&self) -> Vec<TouchMark> {
        let [px, py] = self.spec().plate;
        let mut marks: Vec<TouchMark> = Vec::new();
        for (sx, sy) in PLATE_POINTS {
            let plate_corner = Point3::new(sx * px / 2.0, sy * py / 2.0, 0.0);
            let nearest = self
                .tags()
                .iter()
                .flat_map(|t| {
                    self.corners(t.id).into_iter().flat_map(move |c| {
                        c.into_iter().enumerate().map(move |(k, p)| (t.id, k, p))
                    })
                })
                .min_by(|a, b| {
                    let da = (a.2 - plate_corner).norm();
                    let db = (b.2 - plate_corner).norm();
                    da.total_cmp(&db)
                });
            let Some((tag, corner, point)) = nearest else {
                continue;
            };
            if marks.iter().any(|m| (m.point - point).norm() < 1e-9) {
                continue;
            }
            marks.push(TouchMark {
                name: format!(
                    "{} corner of tag {tag} (outer corner of its black border)",
                    CORNER_NAMES[corner]
                ),
                tag,
                corner,
                point,
            });
        }
        marks
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::BoardSpec;

    #[test]
    fn the_seed_board_is_touched_at_the_outer_corners_of_its_corner_tags() {
        let marks = Board::seed().touch_marks();
        let got: Vec<_> = marks
            .iter()
            .map(|m| (m.tag, m.corner, m.point.x, m.point.y))
            .collect();
        assert_eq!(
            got,
            vec![
                (0, 3, -0.095, 0.095),
                (4, 2, 0.095, 0.095),
                (15, 1, 0.095, -0.095),
                (11, 0, -0.095, -0.095),
                (2, 2, 0.015, 0.095),
                (8, 1, 0.095, -0.015),
                (13, 0, -0.015, -0.095),
                (7, 0, -0.095, -0.015),
            ]
        );
        assert_eq!(
            marks[0].name,
            "top-left corner of tag 0 (outer corner of its black border)"
        );
    }

    #[test]
    fn each_mark_is_a_printed_black_corner_with_white_outside() {
        let board = Board::seed();
        for m in board.touch_marks() {
            // 0.2 mm diagonally inside the mark is the black border; outside, the quiet zone.
            let centre = board.tag(m.tag).unwrap().center;
            let (sx, sy) = (
                (m.point.x - centre.x).signum(),
                (m.point.y - centre.y).signum(),
            );
            assert!(board.is_black(m.point.x - sx * 2e-4, m.point.y - sy * 2e-4));
            assert!(!board.is_black(m.point.x + sx * 2e-4, m.point.y + sy * 2e-4));
            assert!(!board.is_black(m.point.x - sx * 2e-4, m.point.y + sy * 2e-4));
        }
    }

    #[test]
    fn a_one_tag_board_is_touched_at_that_tag_s_four_corners() {
        let mut spec = BoardSpec::seed();
        spec.grid = [1, 1];
        spec.removed = None;
        spec.plate = [0.05, 0.05];
        let marks = Board::new(spec).unwrap().touch_marks();
        assert_eq!(marks.len(), 4);
        assert!(marks.iter().all(|m| m.tag == 0));
        let corners: Vec<_> = marks.iter().map(|m| m.corner).collect();
        assert_eq!(corners, vec![3, 2, 1, 0]);
    }
}
