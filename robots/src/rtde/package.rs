//! RTDE packages: framing, and the encode/decode of every package type in both directions,
//! for protocol versions 1 and 2.
//!
//! Decoding works on one frame's payload (at most 65 532 bytes, bounded by the u16 size field),
//! never panics, and allocates at most a small multiple of the payload length.

use super::types::{DataType, Slot};
use thiserror::Error;

/// Bytes of the package header: u16 size (header included) + u8 type.
pub const HEADER_LEN: usize = 3;
/// Largest payload a package can carry.
pub const MAX_PAYLOAD: usize = u16::MAX as usize - HEADER_LEN;
/// Largest comma-separated name list a controller accepts in a recipe setup.
pub const MAX_NAMES_LEN: usize = 2048;

/// Package type byte for request protocol version (`V`).
pub const TYPE_PROTOCOL_VERSION: u8 = b'V';
/// Package type byte for get controller version (`v`).
pub const TYPE_CONTROLLER_VERSION: u8 = b'v';
/// Package type byte for text messages (`M`).
pub const TYPE_TEXT_MESSAGE: u8 = b'M';
/// Package type byte for data packages (`U`).
pub const TYPE_DATA: u8 = b'U';
/// Package type byte for setup outputs (`O`).
pub const TYPE_SETUP_OUTPUTS: u8 = b'O';
/// Package type byte for setup inputs (`I`).
pub const TYPE_SETUP_INPUTS: u8 = b'I';
/// Package type byte for start (`S`).
pub const TYPE_START: u8 = b'S';
/// Package type byte for pause (`P`).
pub const TYPE_PAUSE: u8 = b'P';

/// RTDE protocol version of a connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Protocol {
    /// Version 1: no output frequency, no recipe id in output data, short text messages.
    V1,
    /// Version 2.
    V2,
}

impl Protocol {
    /// The number sent in the `V` request.
    pub const fn number(self) -> u16 {
        match self {
            Protocol::V1 => 1,
            Protocol::V2 => 2,
        }
    }

    /// Parses a version number; `None` for unsupported ones.
    pub const fn from_number(n: u16) -> Option<Protocol> {
        match n {
            1 => Some(Protocol::V1),
            2 => Some(Protocol::V2),
            _ => None,
        }
    }
}

/// Why a package could not be decoded or encoded.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CodecError {
    /// The size field is smaller than the header.
    #[error("package size {0} is smaller than the 3-byte header")]
    SizeTooSmall(u16),
    /// The payload is shorter than its type requires.
    #[error("package '{ty}' truncated: need {need} bytes, got {got}")]
    Truncated {
        /// Package type.
        ty: char,
        /// Bytes needed.
        need: usize,
        /// Bytes present.
        got: usize,
    },
    /// The payload is longer than its type allows.
    #[error("package '{ty}' has {extra} unexpected trailing bytes")]
    TrailingBytes {
        /// Package type.
        ty: char,
        /// Extra bytes.
        extra: usize,
    },
    /// The type byte is not an RTDE package type.
    #[error("unknown package type {0:#04x}")]
    UnknownType(u8),
    /// Text that must be ASCII is not.
    #[error("package '{0}' carries non-ASCII text")]
    NotAscii(char),
    /// A recipe's name list is over 2 048 bytes.
    #[error("name list of {0} bytes exceeds the 2048-byte limit")]
    NamesTooLong(usize),
    /// A recipe names no variable.
    #[error("recipe names no variable")]
    EmptyRecipe,
    /// A setup reply carries a word that is no data type.
    #[error("unknown data type {0:?}")]
    UnknownDataType(String),
    /// The output frequency is not a positive finite number.
    #[error("invalid output frequency {0}")]
    BadFrequency(f64),
    /// The encoded package would not fit in a u16 size.
    #[error("package payload of {0} bytes does not fit in a package")]
    TooLarge(usize),
    /// A text field of a v2 message is over 255 bytes.
    #[error("text field of {0} bytes is over 255 bytes")]
    TextTooLong(usize),
}

/// A text message (`M`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TextMessage {
    /// The message.
    pub message: String,
    /// Where it comes from (empty in v1).
    pub source: String,
    /// 0 exception, 1 error, 2 warning, 3 info.
    pub level: u8,
}

/// Controller software version (`v` reply).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControllerVersion {
    /// Major (5 for e-Series).
    pub major: u32,
    /// Minor.
    pub minor: u32,
    /// Bugfix.
    pub bugfix: u32,
    /// Build.
    pub build: u32,
}

/// A package sent by a client to the controller.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// `V`: ask for a protocol version.
    ProtocolVersion(u16),
    /// `v`: ask for the controller version.
    ControllerVersion,
    /// `O`: set up the output recipe; `frequency` is `None` in v1.
    SetupOutputs {
        /// Output frequency in Hz (v2 only).
        frequency: Option<f64>,
        /// Variable names.
        names: Vec<String>,
    },
    /// `I`: set up an input recipe.
    SetupInputs {
        /// Variable names.
        names: Vec<String>,
    },
    /// `S`: start streaming.
    Start,
    /// `P`: pause streaming.
    Pause,
    /// `U`: input values for a recipe (raw, decode with its recipe).
    Data {
        /// Input recipe id.
        recipe_id: u8,
        /// The encoded values.
        payload: Vec<u8>,
    },
    /// `M`: a text message.
    Text(TextMessage),
}

/// A package sent by the controller to a client.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// `V`: whether the version was accepted.
    ProtocolVersion {
        /// Accepted.
        accepted: bool,
    },
    /// `v`: the controller version.
    ControllerVersion(ControllerVersion),
    /// `O`: output recipe id (v2 only) and one slot per name.
    SetupOutputs {
        /// Recipe id, `None` in v1.
        recipe_id: Option<u8>,
        /// One answer per requested name.
        slots: Vec<Slot>,
    },
    /// `I`: input recipe id (0 when refused) and one slot per name.
    SetupInputs {
        /// Recipe id.
        recipe_id: u8,
        /// One answer per requested name.
        slots: Vec<Slot>,
    },
    /// `S`: whether streaming started.
    Start {
        /// Accepted.
        accepted: bool,
    },
    /// `P`: whether streaming paused.
    Pause {
        /// Accepted.
        accepted: bool,
    },
    /// `U`: output values (raw, decode with the output recipe).
    Data {
        /// Output recipe id, `None` in v1.
        recipe_id: Option<u8>,
        /// The encoded values.
        payload: Vec<u8>,
    },
    /// `M`: a text message.
    Text(TextMessage),
}

/// A complete frame found at the front of a buffer: type byte, payload, bytes consumed.
pub type Frame<'a> = (u8, &'a [u8], usize);

/// Splits the first complete package off `buf`: `Ok(None)` when more bytes are needed,
/// otherwise the type byte, the payload and the total length consumed.
pub fn split_frame(buf: &[u8]) -> Result<Option<Frame<'_>>, CodecError> {
    if buf.len() < HEADER_LEN {
        return Ok(None);
    }
    let size = u16::from_be_bytes([buf[0], buf[1]]);
    if usize::from(size) < HEADER_LEN {
        return Err(CodecError::SizeTooSmall(size));
    }
    let size = usize::from(size);
    if buf.len() < size {
        return Ok(None);
    }
    Ok(Some((buf[2], &buf[HEADER_LEN..size], size)))
}

/// Writes a header + payload into `out` (cleared first).
fn frame(ty: u8, out: &mut Vec<u8>, body: impl FnOnce(&mut Vec<u8>)) -> Result<(), CodecError> {
    out.clear();
    out.extend_from_slice(&[0, 0, ty]);
    body(out);
    let len = out.len();
    let size = u16::try_from(len).map_err(|_| CodecError::TooLarge(len - HEADER_LEN))?;
    out[..2].copy_from_slice(&size.to_be_bytes());
    Ok(())
}

/// Parses a comma-separated ASCII name list, dropping one empty trailing name (ur_rtde quirk).
pub fn parse_names(ty: u8, bytes: &[u8]) -> Result<Vec<String>, CodecError> {
    if bytes.len() > MAX_NAMES_LEN {
        return Err(CodecError::NamesTooLong(bytes.len()));
    }
    let text = ascii(ty, bytes)?;
    let mut names: Vec<String> = text.split(',').map(|s| s.trim().to_owned()).collect();
    if names.len() > 1 && names.last().is_some_and(|s| s.is_empty()) {
        names.pop();
    }
    if names.iter().all(|n| n.is_empty()) {
        return Err(CodecError::EmptyRecipe);
    }
    Ok(names)
}

fn ascii(ty: u8, bytes: &[u8]) -> Result<&str, CodecError> {
    if !bytes.is_ascii() {
        return Err(CodecError::NotAscii(char::from(ty)));
    }
    std::str::from_utf8(bytes).map_err(|_| CodecError::NotAscii(char::from(ty)))
}

fn parse_slots(ty: u8, bytes: &[u8]) -> Result<Vec<Slot>, CodecError> {
    let text = ascii(ty, bytes)?;
    text.split(',')
        .filter(|s| !s.is_empty())
        .map(|w| Slot::from_wire_name(w).ok_or_else(|| CodecError::UnknownDataType(w.into())))
        .collect()
}

fn join_names<S: AsRef<str>>(names: &[S]) -> Result<String, CodecError> {
    let joined = names
        .iter()
        .map(AsRef::as_ref)
        .collect::<Vec<_>>()
        .join(",");
    if joined.len() > MAX_NAMES_LEN {
        return Err(CodecError::NamesTooLong(joined.len()));
    }
    if !joined.is_ascii() {
        return Err(CodecError::NotAscii('O'));
    }
    Ok(joined)
}

fn exact(ty: u8, payload: &[u8], len: usize) -> Result<(), CodecError> {
    match payload.len().cmp(&len) {
        std::cmp::Ordering::Less => Err(CodecError::Truncated {
            ty: char::from(ty),
            need: len,
            got: payload.len(),
        }),
        std::cmp::Ordering::Greater => Err(CodecError::TrailingBytes {
            ty: char::from(ty),
            extra: payload.len() - len,
        }),
        std::cmp::Ordering::Equal => Ok(()),
    }
}

fn need(ty: u8, payload: &[u8], len: usize) -> Result<(), CodecError> {
    if payload.len() < len {
        return Err(CodecError::Truncated {
            ty: char::from(ty),
            need: len,
            got: payload.len(),
        });
    }
    Ok(())
}

fn decode_text(ty: u8, payload: &[u8], protocol: Protocol) -> Result<TextMessage, CodecError> {
    let lossy = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    match protocol {
        Protocol::V1 => {
            need(ty, payload, 1)?;
            Ok(TextMessage {
                level: payload[0],
                message: lossy(&payload[1..]),
                source: String::new(),
            })
        }
        Protocol::V2 => {
            need(ty, payload, 1)?;
            let mlen = usize::from(payload[0]);
            need(ty, payload, 1 + mlen + 1)?;
            let message = lossy(&payload[1..1 + mlen]);
            let slen = usize::from(payload[1 + mlen]);
            exact(ty, payload, 1 + mlen + 1 + slen + 1)?;
            let source = lossy(&payload[2 + mlen..2 + mlen + slen]);
            Ok(TextMessage {
                message,
                source,
                level: payload[2 + mlen + slen],
            })
        }
    }
}

fn encode_text(t: &TextMessage, protocol: Protocol, out: &mut Vec<u8>) -> Result<(), CodecError> {
    match protocol {
        Protocol::V1 => frame(TYPE_TEXT_MESSAGE, out, |o| {
            o.push(t.level);
            o.extend_from_slice(t.message.as_bytes());
        }),
        Protocol::V2 => {
            for field in [&t.message, &t.source] {
                if field.len() > 255 {
                    return Err(CodecError::TextTooLong(field.len()));
                }
            }
            frame(TYPE_TEXT_MESSAGE, out, |o| {
                o.push(t.message.len() as u8);
                o.extend_from_slice(t.message.as_bytes());
                o.push(t.source.len() as u8);
                o.extend_from_slice(t.source.as_bytes());
                o.push(t.level);
            })
        }
    }
}

fn u8_flag(ty: u8, payload: &[u8]) -> Result<bool, CodecError> {
    exact(ty, payload, 1)?;
    Ok(payload[0] != 0)
}

impl Request {
    /// Decodes a client package of type `ty` from its payload.
    pub fn decode(ty: u8, payload: &[u8], protocol: Protocol) -> Result<Request, CodecError> {
        match ty {
            TYPE_PROTOCOL_VERSION => {
                exact(ty, payload, 2)?;
                Ok(Request::ProtocolVersion(u16::from_be_bytes([
                    payload[0], payload[1],
                ])))
            }
            TYPE_CONTROLLER_VERSION => exact(ty, payload, 0).map(|()| Request::ControllerVersion),
            TYPE_SETUP_OUTPUTS => match protocol {
                Protocol::V1 => Ok(Request::SetupOutputs {
                    frequency: None,
                    names: parse_names(ty, payload)?,
                }),
                Protocol::V2 => {
                    need(ty, payload, 8)?;
                    let f = f64::from_be_bytes(payload[..8].try_into().unwrap_or([0; 8]));
                    Ok(Request::SetupOutputs {
                        frequency: Some(f),
                        names: parse_names(ty, &payload[8..])?,
                    })
                }
            },
            TYPE_SETUP_INPUTS => Ok(Request::SetupInputs {
                names: parse_names(ty, payload)?,
            }),
            TYPE_START => exact(ty, payload, 0).map(|()| Request::Start),
            TYPE_PAUSE => exact(ty, payload, 0).map(|()| Request::Pause),
            TYPE_DATA => {
                need(ty, payload, 1)?;
                Ok(Request::Data {
                    recipe_id: payload[0],
                    payload: payload[1..].to_vec(),
                })
            }
            TYPE_TEXT_MESSAGE => decode_text(ty, payload, protocol).map(Request::Text),
            other => Err(CodecError::UnknownType(other)),
        }
    }

    /// Encodes this package (header included) into `out`, replacing its contents.
    pub fn encode(&self, protocol: Protocol, out: &mut Vec<u8>) -> Result<(), CodecError> {
        match self {
            Request::ProtocolVersion(v) => frame(TYPE_PROTOCOL_VERSION, out, |o| {
                o.extend_from_slice(&v.to_be_bytes())
            }),
            Request::ControllerVersion => frame(TYPE_CONTROLLER_VERSION, out, |_| {}),
            Request::SetupOutputs { frequency, names } => {
                let joined = join_names(names)?;
                frame(TYPE_SETUP_OUTPUTS, out, |o| {
                    if protocol == Protocol::V2 {
                        o.extend_from_slice(&frequency.unwrap_or(125.0).to_be_bytes());
                    }
                    o.extend_from_slice(joined.as_bytes());
                })
            }
            Request::SetupInputs { names } => {
                let joined = join_names(names)?;
                frame(TYPE_SETUP_INPUTS, out, |o| {
                    o.extend_from_slice(joined.as_bytes())
                })
            }
            Request::Start => frame(TYPE_START, out, |_| {}),
            Request::Pause => frame(TYPE_PAUSE, out, |_| {}),
            Request::Data { recipe_id, payload } => frame(TYPE_DATA, out, |o| {
                o.push(*recipe_id);
                o.extend_from_slice(payload);
            }),
            Request::Text(t) => encode_text(t, protocol, out),
        }
    }
}

impl Reply {
    /// Decodes a controller package of type `ty` from its payload.
    pub fn decode(ty: u8, payload: &[u8], protocol: Protocol) -> Result<Reply, CodecError> {
        match ty {
            TYPE_PROTOCOL_VERSION => Ok(Reply::ProtocolVersion {
                accepted: u8_flag(ty, payload)?,
            }),
            TYPE_CONTROLLER_VERSION => {
                exact(ty, payload, 16)?;
                let at = |i: usize| {
                    u32::from_be_bytes(payload[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]))
                };
                Ok(Reply::ControllerVersion(ControllerVersion {
                    major: at(0),
                    minor: at(1),
                    bugfix: at(2),
                    build: at(3),
                }))
            }
            TYPE_SETUP_OUTPUTS => match protocol {
                Protocol::V1 => Ok(Reply::SetupOutputs {
                    recipe_id: None,
                    slots: parse_slots(ty, payload)?,
                }),
                Protocol::V2 => {
                    need(ty, payload, 1)?;
                    Ok(Reply::SetupOutputs {
                        recipe_id: Some(payload[0]),
                        slots: parse_slots(ty, &payload[1..])?,
                    })
                }
            },
            TYPE_SETUP_INPUTS => {
                need(ty, payload, 1)?;
                Ok(Reply::SetupInputs {
                    recipe_id: payload[0],
                    slots: parse_slots(ty, &payload[1..])?,
                })
            }
            TYPE_START => Ok(Reply::Start {
                accepted: u8_flag(ty, payload)?,
            }),
            TYPE_PAUSE => Ok(Reply::Pause {
                accepted: u8_flag(ty, payload)?,
            }),
            TYPE_DATA => match protocol {
                Protocol::V1 => Ok(Reply::Data {
                    recipe_id: None,
                    payload: payload.to_vec(),
                }),
                Protocol::V2 => {
                    need(ty, payload, 1)?;
                    Ok(Reply::Data {
                        recipe_id: Some(payload[0]),
                        payload: payload[1..].to_vec(),
                    })
                }
            },
            TYPE_TEXT_MESSAGE => decode_text(ty, payload, protocol).map(Reply::Text),
            other => Err(CodecError::UnknownType(other)),
        }
    }

    /// Encodes this package (header included) into `out`, replacing its contents.
    pub fn encode(&self, protocol: Protocol, out: &mut Vec<u8>) -> Result<(), CodecError> {
        let slots_text = |slots: &[Slot]| {
            slots
                .iter()
                .map(|s| s.wire_name())
                .collect::<Vec<_>>()
                .join(",")
        };
        match self {
            Reply::ProtocolVersion { accepted } => {
                frame(TYPE_PROTOCOL_VERSION, out, |o| o.push(u8::from(*accepted)))
            }
            Reply::ControllerVersion(v) => frame(TYPE_CONTROLLER_VERSION, out, |o| {
                for x in [v.major, v.minor, v.bugfix, v.build] {
                    o.extend_from_slice(&x.to_be_bytes());
                }
            }),
            Reply::SetupOutputs { recipe_id, slots } => {
                let text = slots_text(slots);
                frame(TYPE_SETUP_OUTPUTS, out, |o| {
                    if protocol == Protocol::V2 {
                        o.push(recipe_id.unwrap_or(0));
                    }
                    o.extend_from_slice(text.as_bytes());
                })
            }
            Reply::SetupInputs { recipe_id, slots } => {
                let text = slots_text(slots);
                frame(TYPE_SETUP_INPUTS, out, |o| {
                    o.push(*recipe_id);
                    o.extend_from_slice(text.as_bytes());
                })
            }
            Reply::Start { accepted } => frame(TYPE_START, out, |o| o.push(u8::from(*accepted))),
            Reply::Pause { accepted } => frame(TYPE_PAUSE, out, |o| o.push(u8::from(*accepted))),
            Reply::Data { recipe_id, payload } => frame(TYPE_DATA, out, |o| {
                if protocol == Protocol::V2 {
                    o.push(recipe_id.unwrap_or(0));
                }
                o.extend_from_slice(payload);
            }),
            Reply::Text(t) => encode_text(t, protocol, out),
        }
    }
}

/// Validates a v2 output frequency (positive and finite).
pub fn check_frequency(f: f64) -> Result<f64, CodecError> {
    if f.is_finite() && f > 0.0 {
        Ok(f)
    } else {
        Err(CodecError::BadFrequency(f))
    }
}

/// The slot types of a setup reply, or the first name that was refused.
pub fn slot_types(slots: &[Slot]) -> Result<Vec<DataType>, (usize, Slot)> {
    slots
        .iter()
        .enumerate()
        .map(|(i, s)| match s {
            Slot::Type(t) => Ok(*t),
            other => Err((i, *other)),
        })
        .collect()
}
