//! One segment of a blended path as the arm model executes it: the type the arm models take
//! and the path module makes (from ur_rtde's injected statements or a `Robot::move_path`).

/// One resolved segment of a path, as the arm model executes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PathMove {
    /// Joint-space move to `q`.
    Joint {
        /// Target joints.
        q: [f64; 6],
        /// Leading-joint speed (rad/s).
        speed: f64,
        /// Leading-joint acceleration (rad/s²).
        accel: f64,
        /// Blend radius (m); 0 stops at the via-point.
        blend: f64,
    },
    /// Straight tool line to `pose`.
    Linear {
        /// Target TCP pose (UR pose vector).
        pose: [f64; 6],
        /// Tool speed (m/s).
        speed: f64,
        /// Tool acceleration (m/s²).
        accel: f64,
        /// Blend radius (m); 0 stops at the via-point.
        blend: f64,
    },
}

impl PathMove {
    /// The blend radius.
    pub fn blend(&self) -> f64 {
        match self {
            PathMove::Joint { blend, .. } | PathMove::Linear { blend, .. } => *blend,
        }
    }

    /// The same move with another blend radius.
    pub fn with_blend(self, r: f64) -> PathMove {
        match self {
            PathMove::Joint {
                q, speed, accel, ..
            } => PathMove::Joint {
                q,
                speed,
                accel,
                blend: r,
            },
            PathMove::Linear {
                pose, speed, accel, ..
            } => PathMove::Linear {
                pose,
                speed,
                accel,
                blend: r,
            },
        }
    }
}
