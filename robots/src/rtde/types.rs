//! RTDE data types, values and the per-slot answers of a recipe setup.

use std::fmt;

/// One of the ten RTDE data types.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// 1 byte, 0 or 1.
    Bool,
    /// 1 byte unsigned.
    Uint8,
    /// 4 bytes unsigned.
    Uint32,
    /// 4 bytes signed.
    Int32,
    /// 8 bytes unsigned.
    Uint64,
    /// IEEE-754 binary64.
    Double,
    /// 3 doubles.
    Vector3d,
    /// 6 doubles.
    Vector6d,
    /// 6 signed 32-bit integers.
    Vector6Int32,
    /// 6 unsigned 32-bit integers.
    Vector6Uint32,
}

impl DataType {
    /// All ten types, in the order of the RTDE guide.
    pub const ALL: [DataType; 10] = [
        DataType::Bool,
        DataType::Uint8,
        DataType::Uint32,
        DataType::Int32,
        DataType::Uint64,
        DataType::Double,
        DataType::Vector3d,
        DataType::Vector6d,
        DataType::Vector6Int32,
        DataType::Vector6Uint32,
    ];

    /// Encoded size in bytes.
    pub const fn size(self) -> usize {
        match self {
            DataType::Bool | DataType::Uint8 => 1,
            DataType::Uint32 | DataType::Int32 => 4,
            DataType::Uint64 | DataType::Double => 8,
            DataType::Vector3d => 24,
            DataType::Vector6d => 48,
            DataType::Vector6Int32 | DataType::Vector6Uint32 => 24,
        }
    }

    /// The name used on the wire (`DOUBLE`, `VECTOR6D`, ...).
    pub const fn wire_name(self) -> &'static str {
        match self {
            DataType::Bool => "BOOL",
            DataType::Uint8 => "UINT8",
            DataType::Uint32 => "UINT32",
            DataType::Int32 => "INT32",
            DataType::Uint64 => "UINT64",
            DataType::Double => "DOUBLE",
            DataType::Vector3d => "VECTOR3D",
            DataType::Vector6d => "VECTOR6D",
            DataType::Vector6Int32 => "VECTOR6INT32",
            DataType::Vector6Uint32 => "VECTOR6UINT32",
        }
    }

    /// Parses a wire name; `None` for anything else.
    pub fn from_wire_name(name: &str) -> Option<DataType> {
        DataType::ALL.into_iter().find(|t| t.wire_name() == name)
    }

    /// The zero value of this type.
    pub const fn zero(self) -> Value {
        match self {
            DataType::Bool => Value::Bool(false),
            DataType::Uint8 => Value::Uint8(0),
            DataType::Uint32 => Value::Uint32(0),
            DataType::Int32 => Value::Int32(0),
            DataType::Uint64 => Value::Uint64(0),
            DataType::Double => Value::Double(0.0),
            DataType::Vector3d => Value::Vector3d([0.0; 3]),
            DataType::Vector6d => Value::Vector6d([0.0; 6]),
            DataType::Vector6Int32 => Value::Vector6Int32([0; 6]),
            DataType::Vector6Uint32 => Value::Vector6Uint32([0; 6]),
        }
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.wire_name())
    }
}

/// A typed RTDE value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// BOOL.
    Bool(bool),
    /// UINT8.
    Uint8(u8),
    /// UINT32.
    Uint32(u32),
    /// INT32.
    Int32(i32),
    /// UINT64.
    Uint64(u64),
    /// DOUBLE.
    Double(f64),
    /// VECTOR3D.
    Vector3d([f64; 3]),
    /// VECTOR6D.
    Vector6d([f64; 6]),
    /// VECTOR6INT32.
    Vector6Int32([i32; 6]),
    /// VECTOR6UINT32.
    Vector6Uint32([u32; 6]),
}

impl Value {
    /// The type of this value.
    pub const fn data_type(&self) -> DataType {
        match self {
            Value::Bool(_) => DataType::Bool,
            Value::Uint8(_) => DataType::Uint8,
            Value::Uint32(_) => DataType::Uint32,
            Value::Int32(_) => DataType::Int32,
            Value::Uint64(_) => DataType::Uint64,
            Value::Double(_) => DataType::Double,
            Value::Vector3d(_) => DataType::Vector3d,
            Value::Vector6d(_) => DataType::Vector6d,
            Value::Vector6Int32(_) => DataType::Vector6Int32,
            Value::Vector6Uint32(_) => DataType::Vector6Uint32,
        }
    }

    /// Appends the big-endian encoding of this value.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match *self {
            Value::Bool(b) => out.push(u8::from(b)),
            Value::Uint8(v) => out.push(v),
            Value::Uint32(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Int32(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Uint64(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Double(v) => out.extend_from_slice(&v.to_be_bytes()),
            Value::Vector3d(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6d(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6Int32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6Uint32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
        }
    }

    /// Decodes one value of type `ty` from the front of `bytes`; `None` when too short.
    /// A BOOL byte other than 0 reads as true.
    pub fn decode(ty: DataType, bytes: &[u8]) -> Option<Value> {
        let b = bytes.get(..ty.size())?;
        let f64_at =
            |i: usize| f64::from_be_bytes(b[8 * i..8 * i + 8].try_into().unwrap_or([0; 8]));
        let u32_at =
            |i: usize| u32::from_be_bytes(b[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]));
        Some(match ty {
            DataType::Bool => Value::Bool(b[0] != 0),
            DataType::Uint8 => Value::Uint8(b[0]),
            DataType::Uint32 => Value::Uint32(u32_at(0)),
            DataType::Int32 => Value::Int32(u32_at(0) as i32),
            DataType::Uint64 => Value::Uint64(u64::from_be_bytes(b.try_into().unwrap_or([0; 8]))),
            DataType::Double => Value::Double(f64_at(0)),
            DataType::Vector3d => Value::Vector3d(std::array::from_fn(f64_at)),
            DataType::Vector6d => Value::Vector6d(std::array::from_fn(f64_at)),
            DataType::Vector6Int32 => {
                Value::Vector6Int32(std::array::from_fn(|i| u32_at(i) as i32))
            }
            DataType::Vector6Uint32 => Value::Vector6Uint32(std::array::from_fn(u32_at)),
        })
    }

    /// The value as f64 when it is a scalar number (BOOL reads 0/1).
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::Bool(b) => Some(f64::from(u8::from(b))),
            Value::Uint8(v) => Some(f64::from(v)),
            Value::Uint32(v) => Some(f64::from(v)),
            Value::Int32(v) => Some(f64::from(v)),
            Value::Uint64(v) => Some(v as f64),
            Value::Double(v) => Some(v),
            _ => None,
        }
    }

    /// The value as i64 when it is an integer scalar or BOOL.
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            Value::Bool(b) => Some(i64::from(b)),
            Value::Uint8(v) => Some(i64::from(v)),
            Value::Uint32(v) => Some(i64::from(v)),
            Value::Int32(v) => Some(i64::from(v)),
            Value::Uint64(v) => i64::try_from(v).ok(),
            _ => None,
        }
    }

    /// The six doubles of a VECTOR6D.
    pub fn as_vector6d(&self) -> Option<[f64; 6]> {
        match *self {
            Value::Vector6d(v) => Some(v),
            _ => None,
        }
    }
}

/// The controller's answer for one name of a recipe setup.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// The variable exists and has this type.
    Type(DataType),
    /// The controller does not know the name.
    NotFound,
    /// The input is owned by another client or a fieldbus.
    InUse,
}

impl Slot {
    /// The word used on the wire.
    pub const fn wire_name(self) -> &'static str {
        match self {
            Slot::Type(t) => t.wire_name(),
            Slot::NotFound => "NOT_FOUND",
            Slot::InUse => "IN_USE",
        }
    }

    /// Parses a wire word; `None` for anything unknown.
    pub fn from_wire_name(name: &str) -> Option<Slot> {
        match name {
            "NOT_FOUND" => Some(Slot::NotFound),
            "IN_USE" => Some(Slot::InUse),
            other => DataType::from_wire_name(other).map(Slot::Type),
        }
    }
}
