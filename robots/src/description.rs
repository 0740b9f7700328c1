//! Robot descriptions from URDF and forward kinematics of a serial chain through them.
//!
//! [`RobotDescription`] validates the link/joint tree of a URDF file (unique links, one parent
//! per link, joints that name existing links, usable joint axes and limits). [`SerialChain`] is the
//! path between two links of that tree (for example `base` → `tool0`), with forward kinematics
//! for its movable joints. The path may climb from the root link to a common ancestor through
//! fixed joints (ROS's `base` frame hangs off `base_link` that way), then descend to the tip.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use thiserror::Error;

use crate::kinematics::JointLimits;

/// Why a robot description could not be loaded or a chain could not be built from it.
#[derive(Debug, Error)]
pub enum DescriptionError {
    /// The URDF file could not be read.
    #[error("{path}: cannot read URDF: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The URDF text is not valid URDF XML.
    #[error("{origin}: invalid URDF: {source}")]
    Parse {
        /// File name or other label of the text.
        origin: String,
        /// The parser's error.
        #[source]
        source: urdf_rs::UrdfError,
    },
    /// Two links share a name.
    #[error("{origin}: link `{link}` is defined twice")]
    DuplicateLink {
        /// File name or other label of the text.
        origin: String,
        /// The repeated name.
        link: String,
    },
    /// A joint names a link that does not exist.
    #[error("{origin}: joint `{joint}` refers to missing link `{link}`")]
    MissingJointLink {
        /// File name or other label of the text.
        origin: String,
        /// The joint.
        joint: String,
        /// The link it names.
        link: String,
    },
    /// A link is the child of more than one joint, so the links do not form a tree.
    #[error("{origin}: link `{link}` is the child of both `{first}` and `{second}`")]
    MultipleParents {
        /// File name or other label of the text.
        origin: String,
        /// The link.
        link: String,
        /// One parent joint.
        first: String,
        /// Another parent joint.
        second: String,
    },
    /// A joint's values cannot be used (zero axis, non-finite origin, empty limit range).
    #[error("{origin}: joint `{joint}`: {reason}")]
    InvalidJoint {
        /// File name or other label of the text.
        origin: String,
        /// The joint.
        joint: String,
        /// What is wrong.
        reason: String,
    },
    /// A joint type serial-chain kinematics does not handle (floating, planar, spherical).
    #[error("{origin}: joint `{joint}` has unsupported type {kind} for a serial chain")]
    UnsupportedJoint {
        /// File name or other label of the text.
        origin: String,
        /// The joint.
        joint: String,
        /// Its URDF type.
        kind: String,
    },
    /// A requested link is not in the description.
    #[error("{origin}: no link named `{link}` (links: {known})")]
    UnknownLink {
        /// File name or other label of the text.
        origin: String,
        /// The requested name.
        link: String,
        /// The names that exist, comma separated.
        known: String,
    },
    /// The two links are in different trees.
    #[error("{origin}: no chain from `{root}` to `{tip}`: they share no ancestor")]
    NoChain {
        /// File name or other label of the text.
        origin: String,
        /// The chain's root link.
        root: String,
        /// The chain's tip link.
        tip: String,
    },
    /// The path from the root up to the common ancestor crosses a movable joint.
    #[error(
        "{origin}: no serial chain from `{root}` to `{tip}`: it would run backwards through \
         movable joint `{joint}`"
    )]
    MovableJointAboveRoot {
        /// File name or other label of the text.
        origin: String,
        /// The chain's root link.
        root: String,
        /// The chain's tip link.
        tip: String,
        /// The movable joint between the root and the common ancestor.
        joint: String,
    },
    /// Following parent joints from a link leads back to it.
    #[error("{origin}: the joints form a cycle through link `{link}`")]
    Cycle {
        /// File name or other label of the text.
        origin: String,
        /// A link on the cycle.
        link: String,
    },
    /// The chain from `base` to `tool0` is not a six-joint Universal Robots arm.
    #[error("{origin}: not a six-joint UR arm from `base` to `tool0`: {reason}")]
    NotUrArm {
        /// File name or other label of the text.
        origin: String,
        /// What differs from a UR arm.
        reason: String,
    },
    /// Forward kinematics got the wrong number of joint values.
    #[error("chain `{root}` → `{tip}` has {expected} movable joints, got {got} values")]
    JointCount {
        /// The chain's root link.
        root: String,
        /// The chain's tip link.
        tip: String,
        /// Movable joints in the chain.
        expected: usize,
        /// Values given.
        got: usize,
    },
}

/// A validated URDF robot description.
#[derive(Clone, Debug)]
pub struct RobotDescription {
    origin: String,
    robot: urdf_rs::Robot,
    /// Index of the joint whose child is each link.
    parent_joint: HashMap<String, usize>,
}

impl RobotDescription {
    /// Loads and validates a URDF file.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, DescriptionError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| DescriptionError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_urdf_str(&text, &path.display().to_string())
    }

    /// Parses and validates URDF text; `origin` names it in error messages (e.g. the file name).
    pub fn from_urdf_str(text: &str, origin: &str) -> Result<Self, DescriptionError> {
        let robot = urdf_rs::read_from_string(text).map_err(|source| DescriptionError::Parse {
            origin: origin.to_owned(),
            source,
        })?;
        Self::from_urdf(robot, origin)
    }

    /// Validates an already parsed URDF model.
    pub fn from_urdf(robot: urdf_rs::Robot, origin: &str) -> Result<Self, DescriptionError> {
        let origin = origin.to_owned();
        let mut links: HashMap<&str, ()> = HashMap::new();
        for link in &robot.links {
            if links.insert(link.name.as_str(), ()).is_some() {
                return Err(DescriptionError::DuplicateLink {
                    origin,
                    link: link.name.clone(),
                });
            }
        }
        let mut parent_joint: HashMap<String, usize> = HashMap::new();
        for (index, joint) in robot.joints.iter().enumerate() {
            for link in [&joint.parent.link, &joint.child.link] {
                if !links.contains_key(link.as_str()) {
                    return Err(DescriptionError::MissingJointLink {
                        origin,
                        joint: joint.name.clone(),
                        link: link.clone(),
                    });
                }
            }
            validate_joint(joint, &origin)?;
            if let Some(&first) = parent_joint.get(&joint.child.link) {
                return Err(DescriptionError::MultipleParents {
                    origin,
                    link: joint.child.link.clone(),
                    first: robot.joints[first].name.clone(),
                    second: joint.name.clone(),
                });
            }
            parent_joint.insert(joint.child.link.clone(), index);
        }
        let description = Self {
            origin,
            robot,
            parent_joint,
        };
        for link in &description.robot.links {
            let (joints, _) = description.ancestry(&link.name);
            if joints.len() > description.robot.joints.len() {
                return Err(DescriptionError::Cycle {
                    origin: description.origin.clone(),
                    link: link.name.clone(),
                });
            }
        }
        Ok(description)
    }

    /// The file name or label the description was read from (errors name it).
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The robot's name in the URDF.
    pub fn name(&self) -> &str {
        &self.robot.name
    }

    /// The parsed URDF model (links with their visual and collision geometry, joints).
    pub fn urdf(&self) -> &urdf_rs::Robot {
        &self.robot
    }

    /// The link named `name`, if any.
    pub fn link(&self, name: &str) -> Option<&urdf_rs::Link> {
        self.robot.links.iter().find(|l| l.name == name)
    }

    fn require_link(&self, name: &str) -> Result<(), DescriptionError> {
        if self.link(name).is_some() {
            return Ok(());
        }
        let known: Vec<&str> = self.robot.links.iter().map(|l| l.name.as_str()).collect();
        Err(DescriptionError::UnknownLink {
            origin: self.origin.clone(),
            link: name.to_owned(),
            known: known.join(", "),
        })
    }

    /// Joint indices from `link` up to the tree's root, nearest first, and the link sequence.
    fn ancestry(&self, link: &str) -> (Vec<usize>, Vec<String>) {
        let mut joints = Vec::new();
        let mut links = vec![link.to_owned()];
        let mut current = link;
        while let Some(&j) = self.parent_joint.get(current) {
            if joints.len() > self.robot.joints.len() {
                break; // a cycle, reported by `from_urdf`
            }
            joints.push(j);
            current = &self.robot.joints[j].parent.link;
            links.push(current.to_owned());
        }
        (joints, links)
    }

    /// The serial chain from link `root` to link `tip`.
    #[allow(non_snake_case)]
    pub fn chain(&self, root: &str, tip: &str) -> Result<SerialChain, DescriptionError> {
        self.require_link(root)?;
        self.require_link(tip)?;
        let (tip_joints, tip_links) = self.ancestry(tip);
        let (root_joints, root_links) = self.ancestry(root);
        // The common ancestor nearest the root, and where it sits on both paths.
        let Some((up_len, down_len)) = root_links
            .iter()
            .enumerate()
            .find_map(|(i, l)| tip_links.iter().position(|t| t == l).map(|j| (i, j)))
        else {
            return Err(DescriptionError::NoChain {
                origin: self.origin.clone(),
                root: root.to_owned(),
                tip: tip.to_owned(),
            });
        };

        // Climb from the root to the common ancestor through fixed joints only.
        let mut ancestor_T_root = Isometry3::identity();
        for &j in &root_joints[..up_len] {
            let joint = &self.robot.joints[j];
            if !matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
                return Err(DescriptionError::MovableJointAboveRoot {
                    origin: self.origin.clone(),
                    root: root.to_owned(),
                    tip: tip.to_owned(),
                    joint: joint.name.clone(),
                });
            }
            ancestor_T_root = pose_to_isometry(&joint.origin) * ancestor_T_root;
        }

        let mut segments = Vec::new();
        let mut fixed = ancestor_T_root.inverse();
        let mut joint_names = Vec::new();
        let mut limits = Vec::new();
        for &j in tip_joints[..down_len].iter().rev() {
            let joint = &self.robot.joints[j];
            let origin = pose_to_isometry(&joint.origin);
            let axis = Unit::new_normalize(Vector3::from(joint.axis.xyz.0));
            let motion = match joint.joint_type {
                urdf_rs::JointType::Fixed => {
                    fixed *= origin;
                    continue;
                }
                urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => Motion::Revolute,
                urdf_rs::JointType::Prismatic => Motion::Prismatic,
                _ => {
                    return Err(DescriptionError::UnsupportedJoint {
                        origin: self.origin.clone(),
                        joint: joint.name.clone(),
                        kind: format!("{:?}", joint.joint_type).to_lowercase(),
                    });
                }
            };
            let limit = match joint.joint_type {
                urdf_rs::JointType::Continuous => UrdfJointLimit {
                    lower: f64::NEG_INFINITY,
                    upper: f64::INFINITY,
                    velocity: joint.limit.velocity,
                    effort: joint.limit.effort,
                },
                _ => UrdfJointLimit {
                    lower: joint.limit.lower,
                    upper: joint.limit.upper,
                    velocity: joint.limit.velocity,
                    effort: joint.limit.effort,
                },
            };
            segments.push(Segment {
                before: fixed * origin,
                axis,
                motion,
                child_link: joint.child.link.clone(),
            });
            fixed = Isometry3::identity();
            joint_names.push(joint.name.clone());
            limits.push(limit);
        }
        Ok(SerialChain {
            root: root.to_owned(),
            tip: tip.to_owned(),
            segments,
            after: fixed,
            joint_names,
            limits,
        })
    }
}

fn validate_joint(joint: &urdf_rs::Joint, origin: &str) -> Result<(), DescriptionError> {
    let invalid = |reason: String| DescriptionError::InvalidJoint {
        origin: origin.to_owned(),
        joint: joint.name.clone(),
        reason,
    };
    let kind = &joint.joint_type;
    if matches!(
        kind,
        urdf_rs::JointType::Floating | urdf_rs::JointType::Planar | urdf_rs::JointType::Spherical
    ) {
        return Err(DescriptionError::UnsupportedJoint {
            origin: origin.to_owned(),
            joint: joint.name.clone(),
            kind: format!("{kind:?}").to_lowercase(),
        });
    }
    let values = joint.origin.xyz.0.iter().chain(joint.origin.rpy.0.iter());
    if !values.into_iter().all(|v| v.is_finite()) {
        return Err(invalid("origin is not finite".into()));
    }
    if matches!(kind, urdf_rs::JointType::Fixed) {
        return Ok(());
    }
    let axis = Vector3::from(joint.axis.xyz.0);
    if !axis.iter().all(|v| v.is_finite()) || axis.norm() < 1e-9 {
        return Err(invalid(format!(
            "axis {:?} has no direction",
            joint.axis.xyz.0
        )));
    }
    if matches!(
        kind,
        urdf_rs::JointType::Revolute | urdf_rs::JointType::Prismatic
    ) {
        let limit = &joint.limit;
        if !(limit.lower.is_finite() && limit.upper.is_finite() && limit.lower < limit.upper) {
            return Err(invalid(format!(
                "limit [{}, {}] is missing or empty",
                limit.lower, limit.upper
            )));
        }
    }
    Ok(())
}

/// The isometry of a URDF `<origin xyz rpy>` (rpy: fixed-axis roll about x, pitch about y,
/// yaw about z, i.e. R = Rz(yaw)·Ry(pitch)·Rx(roll)).
pub fn pose_to_isometry(pose: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = pose.xyz.0;
    let [roll, pitch, yaw] = pose.rpy.0;
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// How a movable joint moves its child.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Motion {
    Revolute,
    Prismatic,
}

/// One movable joint of a chain with the fixed transform preceding it.
#[derive(Clone, Debug)]
struct Segment {
    /// Pose of the joint frame in the previous movable joint's child frame (or the root).
    before: Isometry3<f64>,
    axis: Unit<Vector3<f64>>,
    motion: Motion,
    child_link: String,
}

impl Segment {
    fn motion(&self, value: f64) -> Isometry3<f64> {
        match self.motion {
            Motion::Revolute => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&self.axis, value),
            ),
            Motion::Prismatic => Isometry3::translation(
                self.axis.x * value,
                self.axis.y * value,
                self.axis.z * value,
            ),
        }
    }
}

/// Limits of one movable URDF joint (SI units; ±∞ for continuous joints).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UrdfJointLimit {
    /// Lower position limit (rad or m).
    pub lower: f64,
    /// Upper position limit (rad or m).
    pub upper: f64,
    /// Maximum speed (rad/s or m/s).
    pub velocity: f64,
    /// Maximum effort (N·m or N).
    pub effort: f64,
}

/// A joint axis in the root frame: a point on it and its direction.
pub type JointAxis = (Point3<f64>, Unit<Vector3<f64>>);

/// The movable joints between two links of a description, with forward kinematics.
#[derive(Clone, Debug)]
pub struct SerialChain {
    root: String,
    tip: String,
    segments: Vec<Segment>,
    /// Fixed transform from the last movable joint's child to the tip.
    after: Isometry3<f64>,
    joint_names: Vec<String>,
    limits: Vec<UrdfJointLimit>,
}

impl SerialChain {
    /// The root link.
    pub fn root(&self) -> &str {
        &self.root
    }

    /// The tip link.
    pub fn tip(&self) -> &str {
        &self.tip
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.segments.len()
    }

    /// Names of the movable joints, root first.
    pub fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    /// Limits of the movable joints, root first.
    pub fn limits(&self) -> &[UrdfJointLimit] {
        &self.limits
    }

    /// Position limits as [`JointLimits`] when the chain has exactly six movable joints.
    pub fn joint_limits6(&self) -> Option<JointLimits> {
        if self.limits.len() != 6 {
            return None;
        }
        Some(JointLimits {
            lower: std::array::from_fn(|i| self.limits[i].lower),
            upper: std::array::from_fn(|i| self.limits[i].upper),
        })
    }

    fn check_count(&self, q: &[f64]) -> Result<(), DescriptionError> {
        if q.len() == self.segments.len() {
            Ok(())
        } else {
            Err(DescriptionError::JointCount {
                root: self.root.clone(),
                tip: self.tip.clone(),
                expected: self.segments.len(),
                got: q.len(),
            })
        }
    }

    /// Forward kinematics: `root_T_tip` for joint values `q` (root first).
    pub fn forward(&self, q: &[f64]) -> Result<Isometry3<f64>, DescriptionError> {
        self.check_count(q)?;
        let mut pose = Isometry3::identity();
        for (segment, &value) in self.segments.iter().zip(q) {
            pose = pose * segment.before * segment.motion(value);
        }
        Ok(pose * self.after)
    }

    /// Whether each movable joint turns (revolute or continuous) rather than slides, root first.
    pub fn revolute(&self) -> Vec<bool> {
        self.segments
            .iter()
            .map(|s| s.motion == Motion::Revolute)
            .collect()
    }

    /// Each movable joint's axis in the root frame at joint values `q`: a point on it and its
    /// direction, root first (the axis of joint i does not depend on q_i).
    pub fn joint_axes(&self, q: &[f64]) -> Result<Vec<JointAxis>, DescriptionError> {
        self.check_count(q)?;
        let mut pose = Isometry3::identity();
        let mut out = Vec::with_capacity(self.segments.len());
        for (segment, &value) in self.segments.iter().zip(q) {
            let joint = pose * segment.before;
            out.push((
                joint * Point3::origin(),
                Unit::new_normalize(joint.rotation * segment.axis.into_inner()),
            ));
            pose = joint * segment.motion(value);
        }
        Ok(out)
    }

    /// `root_T_link` for the child link of every movable joint (root first), e.g. to place
    /// collision geometry.
    pub fn link_poses(&self, q: &[f64]) -> Result<Vec<(&str, Isometry3<f64>)>, DescriptionError> {
        self.check_count(q)?;
        let mut pose = Isometry3::identity();
        let mut out = Vec::with_capacity(self.segments.len());
        for (segment, &value) in self.segments.iter().zip(q) {
            pose = pose * segment.before * segment.motion(value);
            out.push((segment.child_link.as_str(), pose));
        }
        Ok(out)
    }
}
