//! The controller side of RTDE: accepts clients, answers setup requests, streams outputs at the
//! requested frequency and applies inputs. What the variables mean is up to a [`Controller`].
//!
//! Bad input gets a protocol-correct answer: a malformed request is answered with an error text
//! message (and, for setups, a refusing reply with recipe id 0), never a panic; a size field
//! below 3 closes the connection because the stream cannot be resynchronised.

use super::frame_io::FrameReader;
use super::package::{
    CodecError, ControllerVersion, Protocol, Reply, Request, TYPE_DATA, TYPE_SETUP_INPUTS,
    TYPE_SETUP_OUTPUTS, TextMessage, check_frequency,
};
use super::recipe::Recipe;
use super::types::{DataType, Slot, Value};
use std::io;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

/// Identifies one client connection.
pub type ConnId = u64;

/// An output variable resolved by the controller: an opaque key and its type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputField {
    /// Controller-specific key.
    pub key: u32,
    /// Canonical type.
    pub ty: DataType,
}

/// An input variable claimed by a connection: an opaque key and its type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputField {
    /// Controller-specific key.
    pub key: u32,
    /// Canonical type.
    pub ty: DataType,
}

/// What an RTDE server needs from the controller behind it.
pub trait Controller: Send + Sync + 'static {
    /// One control-cycle's worth of state.
    type Snapshot: Send + Sync + 'static;
    /// Version reported to `v`.
    fn version(&self) -> ControllerVersion;
    /// Control loop frequency in Hz (the highest output frequency).
    fn control_frequency(&self) -> f64;
    /// Resolves an output variable name.
    fn resolve_output(&self, name: &str) -> Option<OutputField>;
    /// The value of a resolved output in a snapshot.
    fn output_value(&self, snapshot: &Self::Snapshot, key: u32) -> Value;
    /// The control cycle counter of a snapshot.
    fn cycle(&self, snapshot: &Self::Snapshot) -> u64;
    /// Newest snapshots, one per control cycle.
    fn subscribe(&self) -> watch::Receiver<Arc<Self::Snapshot>>;
    /// Claims an input variable for a connection: `Err(NotFound)` or `Err(InUse)` when refused.
    fn claim_input(&self, conn: ConnId, name: &str) -> Result<InputField, Slot>;
    /// Applies input values (already checked against the fields' types).
    fn write_inputs(&self, conn: ConnId, fields: &[InputField], values: &[Value]);
    /// A connection ended: release its inputs.
    fn disconnected(&self, conn: ConnId);
}

/// Faults a test can inject into the stream of every connection.
#[derive(Debug)]
pub struct ServerFaults {
    drop_generation: watch::Sender<u64>,
    state: Mutex<FaultState>,
}

#[derive(Debug, Default)]
struct FaultState {
    delay: Duration,
    skip: u64,
    silent_until: Option<Instant>,
}

impl Default for ServerFaults {
    fn default() -> Self {
        ServerFaults {
            drop_generation: watch::channel(0).0,
            state: Mutex::new(FaultState::default()),
        }
    }
}

impl ServerFaults {
    /// Closes every open RTDE connection now.
    pub fn drop_connections(&self) {
        self.drop_generation.send_modify(|g| *g += 1);
    }

    /// Delays every output package by `delay` (zero restores normal streaming).
    pub fn set_output_delay(&self, delay: Duration) {
        self.lock().delay = delay;
    }

    /// Skips the next `n` output packages (of all connections together).
    pub fn skip_packages(&self, n: u64) {
        self.lock().skip += n;
    }

    /// Sends no output package for `duration` (connections stay open).
    pub fn go_silent(&self, duration: Duration) {
        self.lock().silent_until = Some(Instant::now() + duration);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, FaultState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// What to do with the next output package: `None` to skip it, else the delay.
    fn next_package(&self) -> Option<Duration> {
        let mut s = self.lock();
        if s.silent_until.is_some_and(|t| Instant::now() < t) {
            return None;
        }
        if s.skip > 0 {
            s.skip -= 1;
            return None;
        }
        Some(s.delay)
    }
}

/// Serves RTDE on `listener` until the task is aborted or accepting fails.
pub async fn serve<C: Controller>(
    listener: TcpListener,
    controller: Arc<C>,
    faults: Arc<ServerFaults>,
) -> io::Result<()> {
    static NEXT_CONN: AtomicU64 = AtomicU64::new(1);
    let mut tasks = tokio::task::JoinSet::new();
    loop {
        let (stream, peer) = listener.accept().await?;
        while tasks.try_join_next().is_some() {}
        let conn = NEXT_CONN.fetch_add(1, Ordering::Relaxed);
        let controller = controller.clone();
        let faults = faults.clone();
        tasks.spawn(async move {
            let result = Connection::new(conn, controller.clone(), faults)
                .run(stream)
                .await;
            controller.disconnected(conn);
            match result {
                Ok(()) => tracing::debug!(conn, %peer, "RTDE client left"),
                Err(e) => tracing::debug!(conn, %peer, error = %e, "RTDE connection closed"),
            }
        });
    }
}

struct OutputSetup {
    recipe_id: u8,
    fields: Vec<OutputField>,
    decimation: u64,
}

struct InputSetup {
    recipe: Recipe,
    fields: Vec<InputField>,
}

struct Connection<C: Controller> {
    id: ConnId,
    controller: Arc<C>,
    faults: Arc<ServerFaults>,
    protocol: Protocol,
    output: Option<OutputSetup>,
    inputs: Vec<Option<InputSetup>>,
    streaming: bool,
    out: Vec<u8>,
    values: Vec<Value>,
}

/// Most input recipes one connection may set up (ids are a u8; 255 is plenty).
const MAX_INPUT_RECIPES: usize = 255;

impl<C: Controller> Connection<C> {
    fn new(id: ConnId, controller: Arc<C>, faults: Arc<ServerFaults>) -> Self {
        Connection {
            id,
            controller,
            faults,
            protocol: Protocol::V1,
            output: None,
            inputs: Vec::new(),
            streaming: false,
            out: Vec::with_capacity(1024),
            values: Vec::new(),
        }
    }

    async fn run(mut self, stream: TcpStream) -> io::Result<()> {
        stream.set_nodelay(true)?;
        let (rd, mut wr) = stream.into_split();
        let mut reader = FrameReader::new(rd);
        let mut snapshots = self.controller.subscribe();
        let mut drops = self.faults.drop_generation.subscribe();
        drops.mark_unchanged();
        loop {
            tokio::select! {
                frame = reader.next() => {
                    let request = match frame {
                        Ok(Some((ty, payload))) => Request::decode(ty, payload, self.protocol)
                            .map_err(|e| (ty, e)),
                        Ok(None) => return Ok(()),
                        Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                            self.text(1, &format!("malformed package: {e}"))?;
                            wr.write_all(&self.out).await?;
                            return Err(e);
                        }
                        Err(e) => return Err(e),
                    };
                    match request {
                        Ok(request) => self.handle(request)?,
                        Err((ty, e)) => self.refuse(ty, &e)?,
                    }
                    if !self.out.is_empty() {
                        wr.write_all(&self.out).await?;
                        self.out.clear();
                    }
                }
                changed = snapshots.changed(), if self.streaming => {
                    if changed.is_err() {
                        return Ok(());
                    }
                    let snapshot = snapshots.borrow_and_update().clone();
                    let Some(output) = &self.output else { continue };
                    if !self.controller.cycle(&snapshot).is_multiple_of(output.decimation) {
                        continue;
                    }
                    let Some(delay) = self.faults.next_package() else { continue };
                    if !delay.is_zero() {
                        tokio::time::sleep(delay).await;
                    }
                    self.encode_output(&snapshot);
                    wr.write_all(&self.out).await?;
                    self.out.clear();
                }
                _ = drops.changed() => {
                    return Err(io::Error::new(io::ErrorKind::ConnectionAborted, "fault injection: connection dropped"));
                }
            }
        }
    }

    fn encode_output(&mut self, snapshot: &C::Snapshot) {
        let Some(output) = &self.output else { return };
        self.out.clear();
        self.out.extend_from_slice(&[0, 0, TYPE_DATA]);
        if self.protocol == Protocol::V2 {
            self.out.push(output.recipe_id);
        }
        for f in &output.fields {
            self.controller
                .output_value(snapshot, f.key)
                .encode(&mut self.out);
        }
        // Setup bounded the recipe to far below 64 KiB (2 048 bytes of names, ≤ 48 bytes each).
        let size = u16::try_from(self.out.len()).unwrap_or(u16::MAX);
        self.out[..2].copy_from_slice(&size.to_be_bytes());
    }

    fn push(&mut self, reply: &Reply) -> io::Result<()> {
        let mut buf = Vec::new();
        reply
            .encode(self.protocol, &mut buf)
            .map_err(super::frame_io::invalid)?;
        self.out.extend_from_slice(&buf);
        Ok(())
    }

    fn text(&mut self, level: u8, message: &str) -> io::Result<()> {
        let mut message = message.to_owned();
        message.truncate(200);
        self.push(&Reply::Text(TextMessage {
            message,
            source: "RTDE".into(),
            level,
        }))
    }

    /// Answers a request that could not be decoded.
    fn refuse(&mut self, ty: u8, e: &CodecError) -> io::Result<()> {
        tracing::debug!(conn = self.id, error = %e, "bad RTDE request");
        self.text(1, &e.to_string())?;
        match ty {
            TYPE_SETUP_OUTPUTS => self.push(&Reply::SetupOutputs {
                recipe_id: Some(0),
                slots: Vec::new(),
            }),
            TYPE_SETUP_INPUTS => self.push(&Reply::SetupInputs {
                recipe_id: 0,
                slots: Vec::new(),
            }),
            _ => Ok(()),
        }
    }

    fn handle(&mut self, request: Request) -> io::Result<()> {
        match request {
            Request::ProtocolVersion(v) => {
                let accepted = match Protocol::from_number(v) {
                    Some(p) => {
                        self.protocol = p;
                        true
                    }
                    None => false,
                };
                self.push(&Reply::ProtocolVersion { accepted })
            }
            Request::ControllerVersion => {
                self.push(&Reply::ControllerVersion(self.controller.version()))
            }
            Request::SetupOutputs { frequency, names } => self.setup_outputs(frequency, &names),
            Request::SetupInputs { names } => self.setup_inputs(&names),
            Request::Start => {
                let accepted = self.output.is_some();
                self.streaming = accepted;
                self.push(&Reply::Start { accepted })
            }
            Request::Pause => {
                self.streaming = false;
                self.push(&Reply::Pause { accepted: true })
            }
            Request::Data { recipe_id, payload } => self.apply_inputs(recipe_id, &payload),
            Request::Text(t) => {
                tracing::info!(conn = self.id, level = t.level, source = %t.source, "client says: {}", t.message);
                Ok(())
            }
        }
    }

    fn setup_outputs(&mut self, frequency: Option<f64>, names: &[String]) -> io::Result<()> {
        let max = self.controller.control_frequency();
        let frequency = frequency.unwrap_or(max.min(125.0));
        let slots: Vec<Slot> = names
            .iter()
            .map(|n| match self.controller.resolve_output(n) {
                Some(f) => Slot::Type(f.ty),
                None => Slot::NotFound,
            })
            .collect();
        let valid_frequency = check_frequency(frequency).is_ok() && frequency <= max + 1e-9;
        let all_found = slots.iter().all(|s| matches!(s, Slot::Type(_)));
        if let Some(bad) = names
            .iter()
            .find(|n| self.controller.resolve_output(n).is_none())
        {
            tracing::warn!(conn = self.id, name = %bad, "output variable not found");
        }
        if all_found && valid_frequency {
            let fields = names
                .iter()
                .filter_map(|n| self.controller.resolve_output(n))
                .collect();
            let decimation = (max / frequency).round().max(1.0) as u64;
            self.output = Some(OutputSetup {
                recipe_id: 1,
                fields,
                decimation,
            });
        } else {
            self.output = None;
            self.streaming = false;
            if !valid_frequency {
                self.text(
                    1,
                    &format!("output frequency {frequency} Hz is outside (0, {max}]"),
                )?;
            }
        }
        let recipe_id = u8::from(self.output.is_some());
        self.push(&Reply::SetupOutputs {
            recipe_id: Some(recipe_id),
            slots,
        })
    }

    fn setup_inputs(&mut self, names: &[String]) -> io::Result<()> {
        let mut slots = Vec::with_capacity(names.len());
        let mut fields = Vec::with_capacity(names.len());
        for name in names {
            match self.controller.claim_input(self.id, name) {
                Ok(f) => {
                    slots.push(Slot::Type(f.ty));
                    fields.push(f);
                }
                Err(slot) => slots.push(slot),
            }
        }
        let ok = fields.len() == names.len() && self.inputs.len() < MAX_INPUT_RECIPES;
        let recipe_id = if ok {
            let id = (self.inputs.len() + 1) as u8;
            let types = fields.iter().map(|f| f.ty).collect();
            self.inputs.push(Some(InputSetup {
                recipe: Recipe::new(id, names.to_vec(), types),
                fields,
            }));
            id
        } else {
            0
        };
        self.push(&Reply::SetupInputs { recipe_id, slots })
    }

    fn apply_inputs(&mut self, recipe_id: u8, payload: &[u8]) -> io::Result<()> {
        let setup = usize::from(recipe_id)
            .checked_sub(1)
            .and_then(|i| self.inputs.get(i))
            .and_then(Option::as_ref);
        let Some(setup) = setup else {
            return self.text(
                1,
                &format!("data package for unknown input recipe {recipe_id}"),
            );
        };
        match setup.recipe.decode_into(payload, &mut self.values) {
            Ok(()) => {
                self.controller
                    .write_inputs(self.id, &setup.fields, &self.values);
                Ok(())
            }
            Err(e) => {
                tracing::warn!(conn = self.id, recipe_id, error = %e, "input data package refused");
                self.text(1, &e.to_string())
            }
        }
    }
}
