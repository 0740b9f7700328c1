//! The canonical RTDE variable → type table (output and input variables of e-Series 5.x).

use super::types::DataType;

/// Number of integer, double and low bit registers (0–47 for integers and doubles).
pub const REGISTER_COUNT: usize = 48;

/// Variables a controller can send (the output recipe), with their canonical types.
/// Register families (`output_int_register_N`, ...) are matched separately by [`output_type`].
pub const OUTPUTS: &[(&str, DataType)] = &[
    ("timestamp", DataType::Double),
    ("target_q", DataType::Vector6d),
    ("target_qd", DataType::Vector6d),
    ("target_qdd", DataType::Vector6d),
    ("target_current", DataType::Vector6d),
    ("target_moment", DataType::Vector6d),
    ("actual_q", DataType::Vector6d),
    ("actual_qd", DataType::Vector6d),
    ("actual_current", DataType::Vector6d),
    ("actual_current_window", DataType::Vector6d),
    ("actual_current_as_torque", DataType::Vector6d),
    ("joint_control_output", DataType::Vector6d),
    ("actual_TCP_pose", DataType::Vector6d),
    ("actual_TCP_speed", DataType::Vector6d),
    ("actual_TCP_force", DataType::Vector6d),
    ("target_TCP_pose", DataType::Vector6d),
    ("target_TCP_speed", DataType::Vector6d),
    ("actual_digital_input_bits", DataType::Uint64),
    ("joint_temperatures", DataType::Vector6d),
    ("actual_execution_time", DataType::Double),
    ("robot_mode", DataType::Int32),
    ("joint_mode", DataType::Vector6Int32),
    ("safety_mode", DataType::Int32),
    ("safety_status", DataType::Int32),
    ("actual_tool_accelerometer", DataType::Vector3d),
    ("speed_scaling", DataType::Double),
    ("target_speed_fraction", DataType::Double),
    ("actual_momentum", DataType::Double),
    ("actual_main_voltage", DataType::Double),
    ("actual_robot_voltage", DataType::Double),
    ("actual_robot_current", DataType::Double),
    ("actual_joint_voltage", DataType::Vector6d),
    ("actual_digital_output_bits", DataType::Uint64),
    ("runtime_state", DataType::Uint32),
    ("elbow_position", DataType::Vector3d),
    ("elbow_velocity", DataType::Vector3d),
    ("robot_status_bits", DataType::Uint32),
    ("safety_status_bits", DataType::Uint32),
    ("analog_io_types", DataType::Uint32),
    ("standard_analog_input0", DataType::Double),
    ("standard_analog_input1", DataType::Double),
    ("standard_analog_output0", DataType::Double),
    ("standard_analog_output1", DataType::Double),
    ("io_current", DataType::Double),
    ("euromap67_input_bits", DataType::Uint32),
    ("euromap67_output_bits", DataType::Uint32),
    ("euromap67_24V_voltage", DataType::Double),
    ("euromap67_24V_current", DataType::Double),
    ("tool_mode", DataType::Uint32),
    ("tool_analog_input_types", DataType::Uint32),
    ("tool_analog_input0", DataType::Double),
    ("tool_analog_input1", DataType::Double),
    ("tool_output_voltage", DataType::Int32),
    ("tool_output_current", DataType::Double),
    ("tool_temperature", DataType::Double),
    ("tcp_force_scalar", DataType::Double),
    ("output_bit_registers0_to_31", DataType::Uint32),
    ("output_bit_registers32_to_63", DataType::Uint32),
    ("input_bit_registers0_to_31", DataType::Uint32),
    ("input_bit_registers32_to_63", DataType::Uint32),
    ("tool_output_mode", DataType::Uint8),
    ("tool_digital_output0_mode", DataType::Uint8),
    ("tool_digital_output1_mode", DataType::Uint8),
    ("payload", DataType::Double),
    ("payload_cog", DataType::Vector3d),
    ("payload_inertia", DataType::Vector6d),
    ("script_control_line", DataType::Uint32),
    ("ft_raw_wrench", DataType::Vector6d),
    ("tcp_offset", DataType::Vector6d),
    ("joint_position_deviation_ratio", DataType::Double),
    ("collision_detection_ratio", DataType::Double),
    ("time_scale_source", DataType::Uint32),
    ("speed_slider_fraction", DataType::Double),
    ("speed_slider_mask", DataType::Uint32),
    ("standard_digital_output", DataType::Uint8),
    ("standard_digital_output_mask", DataType::Uint8),
    ("tool_digital_output", DataType::Uint8),
    ("tool_digital_output_mask", DataType::Uint8),
    ("configurable_digital_output", DataType::Uint8),
    ("configurable_digital_output_mask", DataType::Uint8),
];

/// Variables a client can write (the input recipes), with their canonical types.
/// Register families (`input_int_register_N`, ...) are matched separately by [`input_type`].
pub const INPUTS: &[(&str, DataType)] = &[
    ("speed_slider_mask", DataType::Uint32),
    ("speed_slider_fraction", DataType::Double),
    ("standard_digital_output_mask", DataType::Uint8),
    ("standard_digital_output", DataType::Uint8),
    ("configurable_digital_output_mask", DataType::Uint8),
    ("configurable_digital_output", DataType::Uint8),
    ("tool_digital_output_mask", DataType::Uint8),
    ("tool_digital_output", DataType::Uint8),
    ("standard_analog_output_mask", DataType::Uint8),
    ("standard_analog_output_type", DataType::Uint8),
    ("standard_analog_output_0", DataType::Double),
    ("standard_analog_output_1", DataType::Double),
    ("input_bit_registers0_to_31", DataType::Uint32),
    ("input_bit_registers32_to_63", DataType::Uint32),
    ("external_force_torque", DataType::Vector6d),
];

/// A numbered register variable, parsed from its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Register {
    /// `input_int_register_N` (INT32), N in 0..48.
    InputInt(usize),
    /// `input_double_register_N` (DOUBLE), N in 0..48.
    InputDouble(usize),
    /// `input_bit_register_N` (BOOL), N in 64..128.
    InputBit(usize),
    /// `output_int_register_N` (INT32), N in 0..48.
    OutputInt(usize),
    /// `output_double_register_N` (DOUBLE), N in 0..48.
    OutputDouble(usize),
    /// `output_bit_register_N` (BOOL), N in 64..128.
    OutputBit(usize),
}

impl Register {
    /// Parses a register name; `None` when it is not one or the index is out of range.
    pub fn parse(name: &str) -> Option<Register> {
        let index = |prefix: &str| -> Option<usize> {
            let digits = name.strip_prefix(prefix)?;
            if digits.is_empty()
                || digits.len() > 3
                || !digits.bytes().all(|b| b.is_ascii_digit())
                || (digits.len() > 1 && digits.starts_with('0'))
            {
                return None;
            }
            digits.parse().ok()
        };
        let word = |n: usize| (n < REGISTER_COUNT).then_some(n);
        let bit = |n: usize| (64..128).contains(&n).then_some(n);
        if let Some(n) = index("input_int_register_") {
            return word(n).map(Register::InputInt);
        }
        if let Some(n) = index("input_double_register_") {
            return word(n).map(Register::InputDouble);
        }
        if let Some(n) = index("input_bit_register_") {
            return bit(n).map(Register::InputBit);
        }
        if let Some(n) = index("output_int_register_") {
            return word(n).map(Register::OutputInt);
        }
        if let Some(n) = index("output_double_register_") {
            return word(n).map(Register::OutputDouble);
        }
        if let Some(n) = index("output_bit_register_") {
            return bit(n).map(Register::OutputBit);
        }
        None
    }

    /// The canonical type of the register.
    pub const fn data_type(self) -> DataType {
        match self {
            Register::InputInt(_) | Register::OutputInt(_) => DataType::Int32,
            Register::InputDouble(_) | Register::OutputDouble(_) => DataType::Double,
            Register::InputBit(_) | Register::OutputBit(_) => DataType::Bool,
        }
    }

    /// Whether a client may write it through an input recipe.
    pub const fn is_input(self) -> bool {
        matches!(
            self,
            Register::InputInt(_) | Register::InputDouble(_) | Register::InputBit(_)
        )
    }
}

/// Canonical type of a variable a client may request in an output recipe.
/// Input registers can be read back, so they are outputs too.
pub fn output_type(name: &str) -> Option<DataType> {
    if let Some(r) = Register::parse(name) {
        return Some(r.data_type());
    }
    OUTPUTS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
}

/// Canonical type of a variable a client may write through an input recipe.
pub fn input_type(name: &str) -> Option<DataType> {
    if let Some(r) = Register::parse(name) {
        return r.is_input().then_some(r.data_type());
    }
    INPUTS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
}

/// Canonical type of any known variable (output or input).
pub fn canonical_type(name: &str) -> Option<DataType> {
    output_type(name).or_else(|| input_type(name))
}
