//! Commissioning a real cell: board images from the production camera source, and a person at
//! the pendant who jogs the pointer onto each mark while the controller's TCP is read over a
//! receive-only RTDE link (no program runs, nothing is commanded: the arm moves only by the
//! operator's hand).

use std::io::BufRead;
use std::time::Duration;

use nalgebra::Isometry3;
use perception::FrameImage;
use perception::calibration::touch_marks::TouchMark;
use robots::kinematics::from_ur_pose;
use robots::rtde::client::{ClientConfig, RtdeClient};

use super::procedure::{BoardImages, CalibrateError, Operator, StepFuture};
use crate::camera::CameraSource;

/// Board images from a production camera source (full-sensor images, checked by the source).
pub struct CameraImages {
    /// The source.
    pub source: Box<dyn CameraSource>,
    /// How long a capture may wait for its image.
    pub timeout: Duration,
}

impl BoardImages for CameraImages {
    fn capture(&mut self) -> Result<FrameImage, CalibrateError> {
        self.source
            .capture(self.timeout)
            .map(|c| c.image)
            .map_err(|e| CalibrateError::Camera {
                camera: self.source.describe(),
                message: e.to_string(),
            })
    }

    fn describe(&self) -> String {
        self.source.describe()
    }
}

/// A person at the pendant: told on the terminal which mark to touch, confirms with Enter; the
/// TCP is then read from the controller. The controller's TCP must be the pointer's tip (set in
/// its installation), or the pointer's offset given to the procedure.
pub struct PendantOperator {
    client: RtdeClient,
}

impl PendantOperator {
    /// Connects a receive-only RTDE link to `address` (`HOST:PORT`).
    pub async fn connect(address: String) -> Result<Self, CalibrateError> {
        let config = ClientConfig::new(address, &["actual_TCP_pose", "robot_mode", "safety_mode"]);
        let client = RtdeClient::connect(config)
            .await
            .map_err(|e| CalibrateError::Operator(format!("RTDE link to the controller: {e}")))?;
        Ok(Self { client })
    }
}

impl Operator for PendantOperator {
    fn touch<'a>(
        &'a mut self,
        mark: &'a TouchMark,
        index: usize,
        count: usize,
    ) -> StepFuture<'a, Isometry3<f64>> {
        Box::pin(async move {
            eprintln!(
                "touch {index} of {count}: jog the pointer's tip onto {} and press Enter \
                 (q and Enter to stop)",
                mark.name
            );
            let line = tokio::task::spawn_blocking(|| {
                let mut line = String::new();
                std::io::stdin()
                    .lock()
                    .read_line(&mut line)
                    .map(|n| (n, line))
            })
            .await
            .map_err(|e| CalibrateError::Operator(e.to_string()))?
            .map_err(|e| CalibrateError::Operator(format!("reading the terminal: {e}")))?;
            match line {
                (0, _) => return Err(CalibrateError::Operator("the terminal closed".into())),
                (_, l) if l.trim().eq_ignore_ascii_case("q") => {
                    return Err(CalibrateError::Operator("stopped by the operator".into()));
                }
                _ => {}
            }
            let state = self
                .client
                .next_state(Duration::from_secs(1))
                .await
                .map_err(|e| CalibrateError::Operator(format!("reading the TCP: {e}")))?;
            let p = state.vector6d("actual_TCP_pose").ok_or_else(|| {
                CalibrateError::Operator("the controller sent no actual_TCP_pose".into())
            })?;
            Ok(from_ur_pose(&p))
        })
    }
}
