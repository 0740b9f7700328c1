//! The board as a vector file to print at exact scale: every tag's cells as black rectangles
//! (runs of a row merged), the plate's outline to cut along, the tag ids and the touch marks
//! numbered small outside the tags' quiet zones, a 100 mm scale bar to check the print with a
//! ruler, and the board's name and family. Units are millimetres throughout (the page's width
//! and height are given in mm and the viewBox is in mm), so a printer at 100 % reproduces the
//! board exactly.

use std::fmt::Write;

use nalgebra::Point2;
use perception::calibration::Board;

/// White margin around the plate outline, mm.
const MARGIN: f64 = 10.0;
/// Length of the scale bar, mm.
pub const SCALE_BAR_MM: f64 = 100.0;
/// Height of the caption lines and the scale bar below the plate, mm.
const FOOTER: f64 = 34.0;

/// Page size `[width, height]` of the board's print, mm.
pub fn page_size(board: &Board) -> [f64; 2] {
    let [w, h] = plate_mm(board);
    [
        w.max(SCALE_BAR_MM + 20.0) + 2.0 * MARGIN,
        h + 2.0 * MARGIN + FOOTER,
    ]
}

/// The SVG text of `board`, captioned with `name` (the board file's name).
pub fn board_svg(board: &Board, name: &str) -> String {
    let [page_w, page_h] = page_size(board);
    let [plate_w, plate_h] = plate_mm(board);
    let family = board.family();
    let spec = board.spec();
    let cell = spec.tag_size * 1e3 / family.width_at_border as f64;
    let image = cell * family.total_width as f64;
    let quiet = (image - spec.tag_size * 1e3) / 2.0;
    // Board frame (metres, y up, origin at the plate's centre) to page millimetres (y down).
    let left = (page_w - plate_w) / 2.0;
    let to_page = |p: Point2<f64>| {
        Point2::new(
            left + plate_w / 2.0 + p.x * 1e3,
            MARGIN + plate_h / 2.0 - p.y * 1e3,
        )
    };

    let mut s = String::new();
    let _ = writeln!(s, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}mm" height="{}mm" viewBox="0 0 {} {}">"#,
        mm(page_w),
        mm(page_h),
        mm(page_w),
        mm(page_h)
    );
    let _ = writeln!(
        s,
        "<title>{} — {} board, print at 100 % (actual size)</title>",
        escape(name),
        escape(&family.name)
    );
    let _ = writeln!(
        s,
        r##"<rect id="plate" x="{}" y="{}" width="{}" height="{}" fill="#fff" stroke="#000" stroke-width="0.2"/>"##,
        mm(left),
        mm(MARGIN),
        mm(plate_w),
        mm(plate_h)
    );

    for tag in board.tags() {
        let centre = to_page(tag.center);
        let top_left = Point2::new(centre.x - image / 2.0, centre.y - image / 2.0);
        let _ = writeln!(
            s,
            r##"<g id="tag-{}" fill="#000" shape-rendering="crispEdges">"##,
            tag.id
        );
        let w = family.total_width as usize;
        let cells = family.cells(tag.id as usize);
        for row in 0..w {
            let mut column = 0;
            while column < w {
                if cells[row * w + column] {
                    column += 1;
                    continue;
                }
                let start = column;
                while column < w && !cells[row * w + column] {
                    column += 1;
                }
                let _ = writeln!(
                    s,
                    r#"<rect x="{}" y="{}" width="{}" height="{}"/>"#,
                    mm(top_left.x + start as f64 * cell),
                    mm(top_left.y + row as f64 * cell),
                    mm((column - start) as f64 * cell),
                    mm(cell)
                );
            }
        }
        let _ = writeln!(s, "</g>");
    }

    // Tag ids centred below each tag, in the white gap between neighbouring quiet zones (or
    // the plate's margin): never inside a quiet zone, which the detector needs white.
    let gap = (spec.pitch * 1e3 - image).max(0.0);
    let below = board
        .tags()
        .iter()
        .map(|t| plate_h / 2.0 + t.center.y * 1e3 - image / 2.0)
        .fold(f64::INFINITY, f64::min);
    let id_room = gap.min(below);
    if id_room >= 1.0 {
        let size = (0.7 * id_room).min(1.8);
        for tag in board.tags() {
            let centre = to_page(tag.center);
            let _ = writeln!(
                s,
                r##"<text class="tag-id" x="{}" y="{}" font-family="sans-serif" font-size="{}" fill="#777" text-anchor="middle" dominant-baseline="central">{}</text>"##,
                mm(centre.x),
                mm(centre.y + image / 2.0 + id_room / 2.0),
                mm(size),
                tag.id
            );
        }
    }

    // Touch marks: numbered just outside the quiet zone, diagonally off the corner they name.
    let marks = board.touch_marks();
    for (k, mark) in marks.iter().enumerate() {
        let Some(tag) = board.tag(mark.tag) else {
            continue;
        };
        let corner = to_page(Point2::new(mark.point.x, mark.point.y));
        let centre = to_page(tag.center);
        let (sx, sy) = (
            (corner.x - centre.x).signum(),
            (corner.y - centre.y).signum(),
        );
        let out = quiet + 1.2;
        let _ = writeln!(
            s,
            r##"<text class="touch-mark" x="{}" y="{}" font-family="sans-serif" font-size="1.8" font-weight="bold" fill="#444" text-anchor="middle" dominant-baseline="central">{}</text>"##,
            mm(corner.x + sx * out),
            mm(corner.y + sy * out),
            k + 1
        );
    }

    // Caption and scale bar below the plate.
    let caption_y = MARGIN + plate_h + 6.0;
    let ids = match (board.tags().first(), board.tags().last()) {
        (Some(a), Some(b)) => format!("ids {}–{}", a.id, b.id),
        _ => "no tags".into(),
    };
    for (i, line) in [
        format!(
            "{} · {} · {} tags ({ids}), {} mm tags at {} mm pitch · plate {} × {} mm",
            name,
            family.name,
            board.tags().len(),
            mm(spec.tag_size * 1e3),
            mm(spec.pitch * 1e3),
            mm(plate_w),
            mm(plate_h)
        ),
        format!(
            "Print at 100 % (actual size, no fit to page). Touch marks 1–{}: the outer corner \
             of the tag border beside each number.",
            marks.len()
        ),
    ]
    .iter()
    .enumerate()
    {
        let _ = writeln!(
            s,
            r##"<text class="caption" x="{}" y="{}" font-family="sans-serif" font-size="2.6" fill="#000">{}</text>"##,
            mm(MARGIN),
            mm(caption_y + i as f64 * 4.0),
            escape(line)
        );
    }
    let bar_y = caption_y + 16.0;
    let _ = writeln!(
        s,
        r##"<g id="scale-bar" stroke="#000" stroke-width="0.2">"##
    );
    let _ = writeln!(
        s,
        r#"<line x1="{}" y1="{}" x2="{}" y2="{}"/>"#,
        mm(MARGIN),
        mm(bar_y),
        mm(MARGIN + SCALE_BAR_MM),
        mm(bar_y)
    );
    for tick in 0..=10 {
        let x = MARGIN + tick as f64 * SCALE_BAR_MM / 10.0;
        let len = if tick % 5 == 0 { 4.0 } else { 2.0 };
        let _ = writeln!(
            s,
            r#"<line class="tick" x1="{}" y1="{}" x2="{}" y2="{}"/>"#,
            mm(x),
            mm(bar_y - len),
            mm(x),
            mm(bar_y)
        );
    }
    let _ = writeln!(s, "</g>");
    for (tick, label) in [(0.0, "0"), (50.0, "50"), (100.0, "100 mm")] {
        let _ = writeln!(
            s,
            r##"<text x="{}" y="{}" font-family="sans-serif" font-size="2.4" fill="#000" text-anchor="middle">{label}</text>"##,
            mm(MARGIN + tick),
            mm(bar_y + 3.5)
        );
    }
    let _ = writeln!(
        s,
        r##"<text x="{}" y="{}" font-family="sans-serif" font-size="2.6" fill="#000">check with a ruler: 100 mm</text>"##,
        mm(MARGIN + SCALE_BAR_MM + 4.0),
        mm(bar_y)
    );
    let _ = writeln!(s, "</svg>");
    s
}

/// The plate's size in mm.
fn plate_mm(board: &Board) -> [f64; 2] {
    board.spec().plate.map(|v| v * 1e3)
}

/// A length in mm, to 0.1 µm, without trailing zeros.
fn mm(v: f64) -> String {
    let t = format!("{v:.4}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    if t == "-0" { "0".into() } else { t.into() }
}

/// Text safe inside an SVG element.
fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use perception::calibration::BoardSpec;
    use quick_xml::events::{BytesStart, Event};

    use super::*;

    /// One element of the SVG with its attributes and the `id` of the group it lies in.
    #[derive(Debug)]
    struct Element {
        name: String,
        group: Option<String>,
        attributes: BTreeMap<String, String>,
        text: String,
    }

    impl Element {
        fn number(&self, key: &str) -> f64 {
            self.attributes[key].parse().unwrap()
        }
    }

    /// Parses the SVG with an XML parser: the root's attributes and every element below it.
    fn parse(svg: &str) -> (BTreeMap<String, String>, Vec<Element>) {
        let mut reader = quick_xml::Reader::from_str(svg);
        let attributes = |e: &BytesStart| -> BTreeMap<String, String> {
            e.attributes()
                .map(|a| {
                    let a = a.unwrap();
                    let key = String::from_utf8(a.key.as_ref().to_vec()).unwrap();
                    (key, a.unescape_value().unwrap().into_owned())
                })
                .collect()
        };
        let mut root = None;
        let mut elements: Vec<Element> = Vec::new();
        let mut groups: Vec<Option<String>> = Vec::new();
        let mut open: Option<usize> = None;
        loop {
            match reader.read_event().unwrap() {
                Event::Start(e) | Event::Empty(e) if e.name().as_ref() == b"svg" => {
                    root = Some(attributes(&e));
                }
                Event::Start(e) if e.name().as_ref() == b"g" => {
                    groups.push(attributes(&e).get("id").cloned());
                }
                Event::End(e) if e.name().as_ref() == b"g" => {
                    groups.pop();
                }
                Event::Start(e) => {
                    elements.push(Element {
                        name: String::from_utf8(e.name().as_ref().to_vec()).unwrap(),
                        group: groups.last().cloned().flatten(),
                        attributes: attributes(&e),
                        text: String::new(),
                    });
                    open = Some(elements.len() - 1);
                }
                Event::Empty(e) => elements.push(Element {
                    name: String::from_utf8(e.name().as_ref().to_vec()).unwrap(),
                    group: groups.last().cloned().flatten(),
                    attributes: attributes(&e),
                    text: String::new(),
                }),
                Event::Text(t) => {
                    if let Some(i) = open {
                        elements[i].text.push_str(&t.decode().unwrap());
                    }
                }
                Event::GeneralRef(r) => {
                    if let Some(i) = open {
                        let name = r.decode().unwrap();
                        let c = match name.as_ref() {
                            "lt" => '<',
                            "gt" => '>',
                            "amp" => '&',
                            other => panic!("unexpected entity {other}"),
                        };
                        elements[i].text.push(c);
                    }
                }
                Event::End(_) => open = None,
                Event::Eof => break,
                _ => {}
            }
        }
        (root.expect("an <svg> root"), elements)
    }

    /// The black area of each tag's rectangles in cells, from the SVG, and the plate rectangle.
    fn black_cells(board: &Board, elements: &[Element]) -> BTreeMap<u32, Vec<bool>> {
        let family = board.family();
        let w = family.total_width as usize;
        let cell = board.spec().tag_size * 1e3 / family.width_at_border as f64;
        let mut tags = BTreeMap::new();
        for e in elements.iter().filter(|e| e.name == "rect") {
            let Some(id) = e.group.as_deref().and_then(|g| g.strip_prefix("tag-")) else {
                continue;
            };
            let id: u32 = id.parse().unwrap();
            tags.entry(id).or_insert_with(Vec::new).push(e);
        }
        tags.into_iter()
            .map(|(id, rects)| {
                // Cells are counted from where the board puts the tag's image on the page.
                let t = board.tag(id).unwrap();
                let image = cell * w as f64;
                let page = page_size(board);
                let plate = plate_mm(board);
                let x0 = page[0] / 2.0 + t.center.x * 1e3 - image / 2.0;
                let y0 = MARGIN + plate[1] / 2.0 - t.center.y * 1e3 - image / 2.0;
                let mut black = vec![false; w * w];
                for r in rects {
                    let (cx, cy) = ((r.number("x") - x0) / cell, (r.number("y") - y0) / cell);
                    let (cw, ch) = (r.number("width") / cell, r.number("height") / cell);
                    for v in [cx, cy, cw, ch] {
                        assert!((v - v.round()).abs() < 1e-3, "rectangles on the cell grid");
                    }
                    assert!(
                        cx > -0.5
                            && cy > -0.5
                            && cx + cw < w as f64 + 0.5
                            && cy + ch < w as f64 + 0.5
                    );
                    for y in cy.round() as usize..(cy + ch).round() as usize {
                        for x in cx.round() as usize..(cx + cw).round() as usize {
                            assert!(!black[y * w + x], "tag {id}: cell ({x}, {y}) drawn twice");
                            black[y * w + x] = true;
                        }
                    }
                }
                (id, black)
            })
            .collect()
    }

    fn check_print(board: &Board, name: &str) -> Vec<Element> {
        let svg = board_svg(board, name);
        let (root, elements) = parse(&svg);
        let [w, h] = page_size(board);
        assert_eq!(root["width"], format!("{}mm", mm(w)));
        assert_eq!(root["height"], format!("{}mm", mm(h)));
        assert_eq!(root["viewBox"], format!("0 0 {} {}", mm(w), mm(h)));

        // Each tag's black cells are exactly the family's code for its id, and every id is there.
        let tags = black_cells(board, &elements);
        assert_eq!(
            tags.keys().copied().collect::<Vec<_>>(),
            board.tags().iter().map(|t| t.id).collect::<Vec<_>>()
        );
        for (id, black) in &tags {
            let white = board.family().cells(*id as usize);
            let expected: Vec<bool> = white.iter().map(|w| !w).collect();
            assert_eq!(black, &expected, "tag {id}");
            // Every black cell of the tag is the board's black where the renderer prints it.
            let t = board.tag(*id).unwrap();
            let fw = board.family().total_width as usize;
            let cell = board.spec().tag_size / board.family().width_at_border as f64;
            for (k, b) in black.iter().enumerate() {
                let (cx, cy) = ((k % fw) as f64 + 0.5, (k / fw) as f64 + 0.5);
                let x = t.center.x - cell * fw as f64 / 2.0 + cx * cell;
                let y = t.center.y + cell * fw as f64 / 2.0 - cy * cell;
                assert_eq!(board.is_black(x, y), *b, "tag {id} cell {k}");
            }
        }

        // The plate outline is the plate's size.
        let plate = elements
            .iter()
            .find(|e| e.attributes.get("id").map(String::as_str) == Some("plate"))
            .expect("a plate outline");
        let [pw, ph] = plate_mm(board);
        assert!((plate.number("width") - pw).abs() < 1e-9);
        assert!((plate.number("height") - ph).abs() < 1e-9);

        // The scale bar: 100 mm long with 11 ticks 10 mm apart, labelled for a ruler.
        let bar: Vec<&Element> = elements
            .iter()
            .filter(|e| e.group.as_deref() == Some("scale-bar"))
            .collect();
        let line = bar
            .iter()
            .find(|e| !e.attributes.contains_key("class"))
            .unwrap();
        assert!((line.number("x2") - line.number("x1") - 100.0).abs() < 1e-9);
        let ticks: Vec<f64> = bar
            .iter()
            .filter(|e| e.attributes.get("class").map(String::as_str) == Some("tick"))
            .map(|e| e.number("x1") - line.number("x1"))
            .collect();
        assert_eq!(ticks.len(), 11);
        for (k, t) in ticks.iter().enumerate() {
            assert!((t - 10.0 * k as f64).abs() < 1e-9);
        }
        assert!(
            elements
                .iter()
                .any(|e| e.text == "check with a ruler: 100 mm")
        );
        let caption = &elements
            .iter()
            .find(|e| e.attributes.get("class").map(String::as_str) == Some("caption"))
            .unwrap()
            .text;
        assert!(caption.starts_with(&format!("{name} · {}", board.family().name)));
        elements
    }

    #[test]
    fn the_seed_board_prints_its_codes_at_scale_with_ids_marks_and_a_scale_bar() {
        let board = Board::seed();
        let elements = check_print(&board, "seed.toml");
        let [w, h] = page_size(&board);
        assert_eq!((w, h), (230.0, 264.0));
        // Merged runs: 303 rectangles for the 16 tags' 745 black cells.
        let rects = elements
            .iter()
            .filter(|e| e.name == "rect" && e.group.is_some())
            .count();
        let black: usize = board
            .tags()
            .iter()
            .map(|t| {
                board
                    .family()
                    .cells(t.id as usize)
                    .iter()
                    .filter(|w| !**w)
                    .count()
            })
            .sum();
        assert_eq!((rects, black), (303, 745));
        // Ids under each tag, in the gap between quiet zones, and the 8 touch marks.
        let ids: Vec<&str> = elements
            .iter()
            .filter(|e| e.attributes.get("class").map(String::as_str) == Some("tag-id"))
            .map(|e| e.text.as_str())
            .collect();
        assert_eq!(ids, (0..16).map(|i| i.to_string()).collect::<Vec<_>>());
        let first = elements
            .iter()
            .find(|e| e.attributes.get("class").map(String::as_str) == Some("touch-mark"))
            .unwrap();
        // Mark 1 is tag 0's top-left border corner (page x = 10 mm margin + 10 mm from the plate's
        // edge, y likewise) pushed out of the quiet zone (3.75 mm) and 1.2 mm more, diagonally.
        assert_eq!(first.text, "1");
        assert!((first.number("x") - (20.0 - 4.95)).abs() < 1e-9);
        assert!((first.number("y") - (20.0 - 4.95)).abs() < 1e-9);
        let marks = elements
            .iter()
            .filter(|e| e.attributes.get("class").map(String::as_str) == Some("touch-mark"))
            .count();
        assert_eq!(marks, board.touch_marks().len());
    }

    #[test]
    fn other_boards_print_their_own_codes() {
        let board = Board::new(BoardSpec {
            family: "tagStandard41h12".into(),
            tag_size: 0.02,
            pitch: 0.04,
            grid: [3, 2],
            removed: None,
            first_id: 40,
            plate: [0.13, 0.09],
            thickness: 0.002,
        })
        .unwrap();
        let elements = check_print(&board, "small <41h12>.toml");
        assert!(
            elements
                .iter()
                .any(|e| e.text.contains("small <41h12>.toml"))
        );
    }

    /// The print decodes: the SVG's rectangles, read back and rasterised at 8 px/mm (a 30 px
    /// cell), are found by the reference AprilTag detector as every tag of the board, ids and
    /// refined corners where the board puts them on the page (measured: 1e-8 px, the print's
    /// edges lying on pixel boundaries; 0.18 px before refinement).
    #[test]
    fn the_print_read_back_decodes_with_the_reference_detector() {
        use perception::FrameImage;
        use perception::calibration::detect::{DetectorSettings, detect_board};

        let board = Board::seed();
        let (_, elements) = parse(&board_svg(&board, "seed.toml"));
        let [w, h] = page_size(&board);
        let px = 8.0;
        let (width, height) = ((w * px) as u32, (h * px) as u32);
        let mut image = image::GrayImage::from_pixel(width, height, image::Luma([235]));
        for r in elements
            .iter()
            .filter(|e| e.name == "rect" && e.group.is_some())
        {
            let (x0, y0) = (r.number("x") * px, r.number("y") * px);
            let (x1, y1) = (x0 + r.number("width") * px, y0 + r.number("height") * px);
            for y in y0.round() as u32..y1.round() as u32 {
                for x in x0.round() as u32..x1.round() as u32 {
                    image.put_pixel(x, y, image::Luma([20]));
                }
            }
        }
        let frame = FrameImage::full(image::DynamicImage::ImageLuma8(image));
        let sighting = detect_board(&frame, &board, &DetectorSettings::default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(sighting.foreign.is_empty(), "{:?}", sighting.foreign);
        let ids: Vec<u32> = sighting.tags.iter().map(|t| t.id).collect();
        assert_eq!(ids, (0..16).collect::<Vec<_>>());
        let plate_h = plate_mm(&board)[1];
        let mut worst: f64 = 0.0;
        for t in &sighting.tags {
            let corners = board.corners(t.id).unwrap();
            for (seen, c) in t.corners.iter().zip(corners) {
                // Pixel centres at integers: a page point (mm) lies at mm · px − 0.5.
                let x = (w / 2.0 + c.x * 1e3) * px - 0.5;
                let y = (MARGIN + plate_h / 2.0 - c.y * 1e3) * px - 0.5;
                worst = worst.max((seen.x - x).hypot(seen.y - y));
            }
        }
        assert!(
            worst < 1e-3,
            "a corner {worst:.2e} px from where the board puts it"
        );
    }
}
