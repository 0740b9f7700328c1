//! Sustained RTDE output: the virtual controller streams ur_rtde's 56-variable receive recipe at
//! 500 Hz to 3 clients; each client timestamps every data package on arrival. A package is late
//! when it arrives more than 4 ms after the previous one. Pass: ≤ 0.1 % late per client.
//!
//! Prints, per client, the percentiles of the inter-package time (p50, p90, p99, p99.9, max).
//! The control loop runs on absolute deadlines, so one late cycle does not delay the later ones.
//!
//! `cargo bench -p robots --bench rtde_stream` (60 s; RTDE_BENCH_SECS overrides the duration).

#![allow(missing_docs)]

use robots::rtde::frame_io::FrameReader;
use robots::rtde::package::{Protocol, Reply, Request, TYPE_DATA};
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

const NAMES: &str = "timestamp,target_q,target_qd,target_qdd,target_current,target_moment,actual_q,actual_qd,actual_current,joint_control_output,actual_TCP_pose,actual_TCP_speed,actual_TCP_force,target_TCP_pose,target_TCP_speed,actual_digital_input_bits,joint_temperatures,actual_execution_time,robot_mode,joint_mode,safety_mode,actual_tool_accelerometer,speed_scaling,target_speed_fraction,actual_momentum,actual_main_voltage,actual_robot_voltage,actual_robot_current,actual_joint_voltage,actual_digital_output_bits,runtime_state,standard_analog_input0,standard_analog_input1,standard_analog_output0,standard_analog_output1,robot_status_bits,safety_status_bits,payload,payload_cog,ft_raw_wrench";

struct ClientReport {
    gaps: Vec<f64>,
    packages: u64,
    late: u64,
    max_gap: Duration,
    gaps_over_3ms: u64,
    skipped_cycles: u64,
}

async fn client(address: String, run_for: Duration) -> std::io::Result<ClientReport> {
    let stream = TcpStream::connect(address).await?;
    stream.set_nodelay(true)?;
    let (rd, mut wr) = stream.into_split();
    let mut reader = FrameReader::new(rd);
    let p = Protocol::V2;
    let mut buf = Vec::new();
    for req in [
        Request::ProtocolVersion(2),
        Request::SetupOutputs {
            frequency: Some(500.0),
            names: NAMES.split(',').map(str::to_owned).collect(),
        },
        Request::Start,
    ] {
        req.encode(p, &mut buf).expect("encode");
        wr.write_all(&buf).await?;
        let (ty, payload) = reader.next().await?.expect("reply");
        let reply = Reply::decode(ty, payload, p).expect("decode");
        assert!(
            !matches!(reply, Reply::Start { accepted: false } | Reply::Text(_)),
            "{reply:?}"
        );
    }
    let mut report = ClientReport {
        gaps: Vec::with_capacity((run_for.as_secs_f64() * 520.0) as usize),
        packages: 0,
        late: 0,
        max_gap: Duration::ZERO,
        gaps_over_3ms: 0,
        skipped_cycles: 0,
    };
    let start = Instant::now();
    let mut last: Option<(Instant, f64)> = None;
    while start.elapsed() < run_for {
        let Some((ty, payload)) = reader.next().await? else {
            break;
        };
        if ty != TYPE_DATA {
            continue;
        }
        let now = Instant::now();
        let timestamp = f64::from_be_bytes(payload[1..9].try_into().expect("timestamp"));
        if let Some((t, ts)) = last {
            let gap = now - t;
            report.gaps.push(gap.as_secs_f64());
            report.max_gap = report.max_gap.max(gap);
            if gap > Duration::from_millis(4) {
                report.late += 1;
            }
            if gap > Duration::from_millis(3) {
                report.gaps_over_3ms += 1;
            }
            let cycles = ((timestamp - ts) / 0.002).round() as i64;
            if cycles > 1 {
                report.skipped_cycles += (cycles - 1) as u64;
            }
        }
        last = Some((now, timestamp));
        report.packages += 1;
    }
    Ok(report)
}

fn main() {
    let secs: u64 = std::env::var("RTDE_BENCH_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let vur = VirtualUr::start(VirtualUrConfig::ephemeral())
            .await
            .expect("start virtual controller");
        let address = vur.rtde_addr().to_string();
        let run_for = Duration::from_secs(secs);
        let handles: Vec<_> = (0..3)
            .map(|_| tokio::spawn(client(address.clone(), run_for)))
            .collect();
        let mut worst = 0.0f64;
        for (i, h) in handles.into_iter().enumerate() {
            let mut r = h.await.expect("join").expect("client");
            r.gaps.sort_by(f64::total_cmp);
            let pct = |p: f64| {
                let i = ((r.gaps.len() as f64 - 1.0) * p).round() as usize;
                r.gaps.get(i).copied().unwrap_or(f64::NAN) * 1e3
            };
            println!(
                "client {i}: inter-package time p50 {:.3} ms, p90 {:.3} ms, p99 {:.3} ms, p99.9 {:.3} ms, max {:.3} ms",
                pct(0.5),
                pct(0.9),
                pct(0.99),
                pct(0.999),
                pct(1.0)
            );
            let pct = 100.0 * r.late as f64 / r.packages.max(1) as f64;
            worst = worst.max(pct);
            println!(
                "client {i}: {} packages in {secs} s ({:.1} Hz), late (>4 ms) {} = {pct:.4} %, >3 ms {}, max gap {:.2} ms, controller cycles skipped {}",
                r.packages,
                r.packages as f64 / secs as f64,
                r.late,
                r.gaps_over_3ms,
                r.max_gap.as_secs_f64() * 1e3,
                r.skipped_cycles
            );
        }
        println!(
            "control loop: {} cycles, {} overruns",
            vur.loop_stats.cycles.load(Ordering::Relaxed),
            vur.loop_stats.overruns.load(Ordering::Relaxed)
        );
        println!("worst client late fraction {worst:.4} % (limit 0.1 %)");
        assert!(worst <= 0.1, "more than 0.1 % late packages");
    });
}
