//! The evaluation's estimates as a BOP Challenge results file, so that the BOP toolkit can score
//! them beside other methods' (`scene_id,im_id,obj_id,score,R,t,time`; R row-major, t in mm,
//! time in seconds per image).

use std::fmt::Write;

use super::FrameRecord;

/// The method's name in the results file's name.
pub const METHOD: &str = "cell-learned";

/// BOP's name for the results of `dataset` (a folder name) on `split`:
/// `METHOD_DATASET-SPLIT.csv`. The toolkit splits that name at `_` and `-`, so the dataset and
/// split keep only their letters and digits.
pub fn file_name(dataset: &str, split: &str) -> String {
    let plain = |s: &str| -> String { s.chars().filter(char::is_ascii_alphanumeric).collect() };
    format!("{METHOD}_{}-{}.csv", plain(dataset), plain(split))
}

/// Every detection with a pose and an object id, one row each, in frame order; a frame's time
/// is its pipeline's total (−1 when the frame failed).
pub fn results_csv(frames: &[FrameRecord]) -> String {
    let mut csv = String::from("scene_id,im_id,obj_id,score,R,t,time\n");
    let join = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.9}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    for f in frames {
        let time = f.times.as_ref().map_or(-1.0, |t| t.total / 1000.0);
        for d in &f.detections {
            let (Some(pose), Some(obj_id)) = (&d.pose, d.obj_id) else {
                continue;
            };
            let _ = writeln!(
                csv,
                "{},{},{obj_id},{:.6},{},{},{time:.6}",
                f.scene,
                f.image,
                d.confidence.unwrap_or(d.score),
                join(&pose.r),
                join(&pose.t_mm),
            );
        }
    }
    csv
}
