//! The production client against the simulation: the simulated cell behind an in-process virtual
//! UR controller on 127.0.0.1 free ports, driven by `UrRobot` over loopback RTDE. The
//! orchestrator reads the camera, feeder and verdicts from the same shared cell, so outcomes can
//! be compared with the in-process run episode for episode.

use std::net::{IpAddr, Ipv4Addr};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use robots::limited::Limited;
use robots::robot::RobotError;
use robots::ur_robot::{UrRobot, UrRobotConfig};
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use sim::cell::SimCell;
use sim::cell::arm::SimArm;

use super::{HarnessError, SimCellIo, SimSetup};
use crate::camera::CameraError;
use crate::orchestrator::{EpisodeOutput, SplitCell, run_episode};

/// Why an episode over loopback RTDE could not run.
#[derive(Debug, thiserror::Error)]
pub enum OverRtdeError {
    /// The simulated cell or perception could not be set up.
    #[error(transparent)]
    Setup(#[from] HarnessError),
    /// The virtual controller could not bind its loopback ports.
    #[error("virtual controller on 127.0.0.1: {0}")]
    Bind(#[from] std::io::Error),
    /// The RTDE client could not connect to the virtual controller or start our program.
    #[error("connecting to the virtual controller: {0}")]
    Connect(#[from] RobotError),
    /// The simulated camera could not be set up.
    #[error("simulated camera: {0}")]
    Camera(#[from] CameraError),
}

/// One episode's simulated cell behind a running virtual controller, and the client connected
/// to it.
pub struct SimOverRtde {
    /// The virtual controller (drop it to stop it); tests inject faults through it.
    pub controller: VirtualUr,
    /// The production client, connected and running our program.
    pub robot: Limited<UrRobot>,
    /// The simulated cell the controller drives (camera, feeder, verdicts).
    pub cell: Arc<Mutex<SimCell>>,
}

/// Starts `episode`'s simulated cell behind a virtual controller on loopback and connects the
/// production client; `unlock_delay` is how long a protective stop stays locked (5 s on a real
/// UR).
pub async fn connect_sim_over_rtde(
    setup: &SimSetup,
    episode: u32,
    unlock_delay: Duration,
) -> Result<SimOverRtde, OverRtdeError> {
    let cell = setup.cell(episode)?;
    let initial_q = cell.lock().unwrap_or_else(|p| p.into_inner()).joints_now();
    // Loopback only, free ports: nothing outside this machine can reach the simulated cell.
    let config = VirtualUrConfig {
        host: IpAddr::V4(Ipv4Addr::LOCALHOST),
        initial_q,
        unlock_delay,
        ..VirtualUrConfig::ephemeral()
    };
    let controller = VirtualUr::start_with_arm(config, Box::new(SimArm::new(cell.clone()))).await?;
    let mut rc = UrRobotConfig::new("127.0.0.1", setup.engine.knowledge.kinematics.clone());
    rc.rtde_port = controller.rtde_addr().port();
    rc.dashboard_port = controller.dashboard_addr().port();
    rc.script_port = controller.script_addr().port();
    rc.limits = setup.scenario().spec.cell.limits.clone();
    setup.scenario().spec.cell.gripper.configure_ur(&mut rc);
    let robot = UrRobot::connect(rc).await?;
    Ok(SimOverRtde {
        controller,
        robot,
        cell,
    })
}

/// Runs `episode` of the simulated cell over loopback RTDE (see the module docs).
pub async fn sim_episode_over_rtde(
    setup: &SimSetup,
    episode: u32,
) -> Result<EpisodeOutput, OverRtdeError> {
    let mut perception = setup.perception.for_episode(setup.scenario(), episode)?;
    let SimOverRtde {
        controller,
        mut robot,
        cell,
    } = connect_sim_over_rtde(setup, episode, VirtualUrConfig::default().unlock_delay).await?;
    let mut io = sim_cell_io(setup, cell)?;
    let mut cell = SplitCell {
        robot: &mut robot,
        io: &mut io,
    };
    let out = run_episode(setup.engine.context(episode), &mut cell, &mut perception).await;
    drop(robot);
    drop(controller);
    Ok(out)
}

/// The side channels of an episode over RTDE: with learned perception its captures are
/// full-sensor image files read through the camera interface, as in production; keypoint-noise
/// perception reads the true scene.
pub fn sim_cell_io(setup: &SimSetup, cell: Arc<Mutex<SimCell>>) -> Result<SimCellIo, CameraError> {
    if setup.perception.needs_pixels() {
        SimCellIo::through_files(cell)
    } else {
        Ok(SimCellIo::new(cell))
    }
}
