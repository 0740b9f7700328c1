//! The controller's general-purpose registers and standard I/O.

use crate::rtde::variables::REGISTER_COUNT;

/// Input and output registers (integers, doubles, bits) of the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct Registers {
    /// input_int_register_0..47.
    pub input_int: [i32; REGISTER_COUNT],
    /// input_double_register_0..47.
    pub input_double: [f64; REGISTER_COUNT],
    /// input bit registers 0..127 (bit i = register i).
    pub input_bits: u128,
    /// output_int_register_0..47.
    pub output_int: [i32; REGISTER_COUNT],
    /// output_double_register_0..47.
    pub output_double: [f64; REGISTER_COUNT],
    /// output bit registers 0..127.
    pub output_bits: u128,
    /// Which input_double_registers (bit i = register i) the newest input package that wrote
    /// input_int_register_0 also wrote: the parameters that came with the command. A program
    /// tells from it whether an optional argument was sent or the register only holds what an
    /// earlier command left there.
    pub command_doubles: u64,
}

impl Default for Registers {
    fn default() -> Self {
        Registers {
            input_int: [0; REGISTER_COUNT],
            input_double: [0.0; REGISTER_COUNT],
            input_bits: 0,
            output_int: [0; REGISTER_COUNT],
            output_double: [0.0; REGISTER_COUNT],
            output_bits: 0,
            command_doubles: 0,
        }
    }
}

/// Standard, configurable and tool digital outputs and the speed slider.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandardIo {
    /// Standard digital outputs 0–7.
    pub standard_do: u8,
    /// Configurable digital outputs 0–7.
    pub configurable_do: u8,
    /// Tool digital outputs 0–1.
    pub tool_do: u8,
    /// Speed slider fraction 0–1.
    pub speed_slider: f64,
    /// Standard analog outputs 0–1 as `standard_analog_output0/1` report them: volts in the
    /// voltage domain (0–10 V), amperes in the current domain (4–20 mA).
    pub analog_out: [f64; 2],
    /// Whether each standard analog output is in the voltage domain (else current), as the
    /// last `standard_analog_output_type` set it; a program's `set_standard_analog_out` keeps it.
    pub analog_voltage: [bool; 2],
}

impl Default for StandardIo {
    fn default() -> Self {
        StandardIo {
            standard_do: 0,
            configurable_do: 0,
            tool_do: 0,
            speed_slider: 1.0,
            analog_out: [0.004; 2],
            analog_voltage: [false; 2],
        }
    }
}

impl StandardIo {
    /// `actual_digital_output_bits`: standard 0–7, configurable 8–15, tool 16–17.
    pub fn digital_output_bits(&self) -> u64 {
        u64::from(self.standard_do)
            | (u64::from(self.configurable_do) << 8)
            | (u64::from(self.tool_do & 0b11) << 16)
    }

    /// Sets analog output `i` from a ratio 0–1 (clamped) in the voltage (0–10 V) or current
    /// (4–20 mA) domain, as `standard_analog_output_N` with `standard_analog_output_type`.
    pub fn set_analog_output(&mut self, i: usize, ratio: f64, voltage: bool) {
        if i < 2 && ratio.is_finite() {
            let r = ratio.clamp(0.0, 1.0);
            self.analog_out[i] = if voltage { 10.0 * r } else { 0.004 + 0.016 * r };
            self.analog_voltage[i] = voltage;
        }
    }

    /// Analog output `i` as the ratio 0–1 of its domain's range (`None` for no such output).
    pub fn analog_ratio(&self, i: usize) -> Option<f64> {
        let v = *self.analog_out.get(i)?;
        Some(if self.analog_voltage[i] {
            v / 10.0
        } else {
            (v - 0.004) / 0.016
        })
    }

    /// Sets one standard (0–7), configurable (8–15) or tool (16–17) output; false if no such pin.
    pub fn set_digital_output(&mut self, pin: i64, level: bool) -> bool {
        let (reg, bit) = match pin {
            0..=7 => (&mut self.standard_do, pin),
            8..=15 => (&mut self.configurable_do, pin - 8),
            16..=17 => (&mut self.tool_do, pin - 16),
            _ => return false,
        };
        if level {
            *reg |= 1 << bit;
        } else {
            *reg &= !(1 << bit);
        }
        true
    }
}

/// The active payload as set by `set_payload` / `set_target_payload` (and streamed as
/// `payload`, `payload_cog`, `payload_inertia`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Payload {
    /// Mass (kg).
    pub mass: f64,
    /// Centre of gravity in the flange frame (m).
    pub cog: [f64; 3],
    /// Inertia (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) at the centre of gravity (kg m²).
    pub inertia: [f64; 6],
}
