//! The report a person opens: small, images beside it, failures grouped by mechanism, each
//! failed episode listed with a link to its event log.

mod support;

use cell::report::plots::{rate_axis_floor, tick_decimals};

#[test]
fn ticks_0_05_apart_print_with_two_decimals() {
    // An axis to 0.5 with ten ticks: 0.05 apart.
    let d = tick_decimals(0.5, 10);
    let labels: Vec<String> = (0..=10)
        .map(|i| format!("{:.d$}", f64::from(i) * 0.05))
        .collect();
    let mut unique = labels.clone();
    unique.dedup();
    assert_eq!(unique.len(), labels.len(), "{labels:?}");
    assert_eq!(tick_decimals(100.0, 10), 0);
}
use support::{cell, text};

#[test]
fn the_rate_axis_starts_where_99_5_and_100_percent_differ() {
    // 99.5 % (interval down to 97.2 %) and 100 %: the axis starts well above 0.
    let floor = rate_axis_floor(&[97.2, 98.1, 100.0]);
    assert!((90.0..97.2).contains(&floor), "{floor}");
    // A rate far from 100 % keeps the axis at 0.
    assert_eq!(rate_axis_floor(&[40.2, 97.0]), 0.0);
}

#[test]
fn a_noisy_run_reports_mechanisms_and_links_every_failed_episode_to_its_events() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = support::NoisyScenario::new("report");
    let out = tmp.path().display().to_string();
    let o = cell(&[
        "run",
        &scenario.path().display().to_string(),
        "--episodes",
        "40",
        "--pictures",
        "2",
        "--out",
        &out,
        "--quiet",
    ]);
    assert!(
        text(&o).contains("pictures of 2 failed episodes"),
        "{}",
        text(&o)
    );
    assert!(o.status.success(), "{}", text(&o));
    let dir = tmp.path().join("usbc-nominal/all");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    // Plots are files beside the page, not inlined.
    assert!(!html.contains("<svg"), "inline SVG");
    for src in html.split("src=\"").skip(1) {
        let path = &src[..src.find('"').unwrap()];
        assert!(dir.join(path).is_file(), "{path} missing");
    }
    assert!(html.contains("plots/pose_error_step1.svg"));
    let scatter = std::fs::read_to_string(dir.join("plots/pose_error_step1.svg")).unwrap();
    assert!(
        scatter.contains("capture band ±0.145 mm"),
        "no capture band"
    );
    // Numbers do not wrap between value and unit.
    assert!(html.contains("&nbsp;%"));
    // Failures grouped by mechanism, far fewer rows than failures.
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    let failures = summary["failures"].as_u64().unwrap();
    let mechanisms = summary["failure_mechanisms"].as_array().unwrap();
    assert!(failures >= 8, "only {failures} failures at 3 px");
    assert!(mechanisms.len() <= 6, "{mechanisms:?}");
    let grouped: u64 = mechanisms
        .iter()
        .map(|m| m["count"].as_u64().unwrap())
        .sum();
    assert_eq!(grouped, failures);
    assert!(html.contains("missed: lateral offset beyond the capture band"));
    // Every failed episode is listed, linked to an event log that exists.
    let records = std::fs::read_to_string(dir.join("episodes.jsonl")).unwrap();
    let failed: Vec<u64> = records
        .lines()
        .skip(1)
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|r| r["success"] == false)
        .map(|r| r["episode"].as_u64().unwrap())
        .collect();
    assert_eq!(failed.len() as u64, failures);
    for e in failed {
        let link = format!("events/episode-{e:06}.jsonl");
        assert!(
            html.contains(&format!("href=\"{link}\"")),
            "{link} not linked"
        );
        assert!(dir.join(&link).is_file());
    }
}
