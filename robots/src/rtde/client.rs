//! Async RTDE client (tokio): negotiates protocol v2, sets up one output recipe and any number of
//! input recipes, keeps only the newest output state, detects stalls and reconnects with backoff.

use super::frame_io::FrameReader;
use super::package::{
    CodecError, ControllerVersion, Protocol, Reply, Request, TYPE_DATA, slot_types,
};
use super::recipe::{Recipe, RecipeError};
use super::state::{OutputState, RuntimeState};
use super::types::{Slot, Value};
use crate::robot::{RobotMode, SafetyStatus};
use std::io;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::sync::{mpsc, watch};

/// Errors of the RTDE client.
#[derive(Debug, Clone, Error)]
pub enum ClientError {
    /// Socket error (connect, read, write).
    #[error("RTDE I/O error: {0}")]
    Io(String),
    /// The controller sent bytes that are not valid RTDE.
    #[error("RTDE protocol error: {0}")]
    Codec(#[from] CodecError),
    /// The controller refused protocol version 2.
    #[error("controller refused RTDE protocol version {0}")]
    ProtocolRefused(u16),
    /// A recipe variable was refused.
    #[error("controller refused variable {name}: {slot:?}")]
    VariableRefused {
        /// The name.
        name: String,
        /// `NOT_FOUND` or `IN_USE`.
        slot: Slot,
    },
    /// The controller refused the output recipe (e.g. the frequency).
    #[error("controller refused the output recipe")]
    OutputRecipeRefused,
    /// The controller refused to start streaming.
    #[error("controller refused to start streaming")]
    StartRefused,
    /// A reply of another type than expected arrived during setup.
    #[error("expected a '{expected}' reply, got '{got}'")]
    UnexpectedReply {
        /// Expected type.
        expected: char,
        /// Received type.
        got: char,
    },
    /// No reply or package within the allowed time.
    #[error("timed out waiting for {0}")]
    Timeout(&'static str),
    /// Values do not match an input recipe.
    #[error(transparent)]
    Recipe(#[from] RecipeError),
    /// No input recipe with this index was configured.
    #[error("no input recipe #{0}")]
    NoSuchInputRecipe(usize),
    /// The link is down (reconnecting or given up).
    #[error("RTDE link is down")]
    LinkDown,
    /// Reconnection gave up after the configured attempts.
    #[error("gave up reconnecting after {0} attempts")]
    GaveUp(u32),
}

impl From<io::Error> for ClientError {
    fn from(e: io::Error) -> Self {
        ClientError::Io(e.to_string())
    }
}

/// Reconnection backoff: exponential from `initial` to `max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backoff {
    /// First wait.
    pub initial: Duration,
    /// Largest wait.
    pub max: Duration,
    /// Give up after this many failed attempts in a row (`None`: never).
    pub max_attempts: Option<u32>,
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff {
            initial: Duration::from_millis(50),
            max: Duration::from_secs(2),
            max_attempts: None,
        }
    }
}

impl Backoff {
    /// Wait before attempt `n` (0-based).
    pub fn delay(&self, attempt: u32) -> Duration {
        let factor = 2u32.saturating_pow(attempt.min(20));
        self.initial.saturating_mul(factor).min(self.max)
    }
}

/// Client configuration.
#[derive(Debug, Clone)]
pub struct ClientConfig {
    /// Controller address, e.g. `127.0.0.1:30004`.
    pub address: String,
    /// Output frequency in Hz (≤ 500 on e-Series).
    pub frequency: f64,
    /// Output variables.
    pub outputs: Vec<String>,
    /// Input recipes, each a list of variables.
    pub inputs: Vec<Vec<String>>,
    /// No package within this time counts as a stall (the link is then re-established).
    pub stall_timeout: Duration,
    /// Timeout of connect and of each setup reply.
    pub setup_timeout: Duration,
    /// Reconnection policy.
    pub backoff: Backoff,
}

impl ClientConfig {
    /// A configuration with defaults: 500 Hz, 100 ms stall timeout, 2 s setup timeout.
    pub fn new(address: impl Into<String>, outputs: &[&str]) -> ClientConfig {
        ClientConfig {
            address: address.into(),
            frequency: 500.0,
            outputs: outputs.iter().map(|s| (*s).to_owned()).collect(),
            inputs: Vec::new(),
            stall_timeout: Duration::from_millis(100),
            setup_timeout: Duration::from_secs(2),
            backoff: Backoff::default(),
        }
    }

    /// Adds an input recipe; its index is the number of recipes added before it.
    pub fn with_input_recipe(mut self, names: &[&str]) -> ClientConfig {
        self.inputs
            .push(names.iter().map(|s| (*s).to_owned()).collect());
        self
    }
}

/// Health of the RTDE link.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkStatus {
    /// Data flows.
    Streaming,
    /// No package within the stall timeout; reconnecting.
    Stalled,
    /// Reconnecting after a failure; attempt number.
    Reconnecting(u32),
    /// Gave up (see the message).
    Failed(String),
    /// The client was shut down.
    Closed,
}

/// A negotiated connection with its recipes.
struct Session {
    reader: FrameReader<OwnedReadHalf>,
    writer: OwnedWriteHalf,
    output: Arc<Recipe>,
    inputs: Vec<Recipe>,
    version: ControllerVersion,
}

async fn with_timeout<T>(
    d: Duration,
    what: &'static str,
    f: impl Future<Output = Result<T, ClientError>>,
) -> Result<T, ClientError> {
    tokio::time::timeout(d, f)
        .await
        .map_err(|_| ClientError::Timeout(what))?
}

/// Reads replies until one that is not a text message.
async fn read_reply(
    reader: &mut FrameReader<OwnedReadHalf>,
    protocol: Protocol,
) -> Result<Reply, ClientError> {
    loop {
        let Some((ty, payload)) = reader.next().await? else {
            return Err(ClientError::Io("controller closed the connection".into()));
        };
        match Reply::decode(ty, payload, protocol)? {
            Reply::Text(t) => {
                tracing::info!(level = t.level, source = %t.source, "controller says: {}", t.message)
            }
            reply => return Ok(reply),
        }
    }
}

fn unexpected(expected: u8, got: &Reply) -> ClientError {
    let got = match got {
        Reply::ProtocolVersion { .. } => 'V',
        Reply::ControllerVersion(_) => 'v',
        Reply::SetupOutputs { .. } => 'O',
        Reply::SetupInputs { .. } => 'I',
        Reply::Start { .. } => 'S',
        Reply::Pause { .. } => 'P',
        Reply::Data { .. } => 'U',
        Reply::Text(_) => 'M',
    };
    ClientError::UnexpectedReply {
        expected: char::from(expected),
        got,
    }
}

async fn establish(config: &ClientConfig) -> Result<Session, ClientError> {
    let stream = with_timeout(config.setup_timeout, "connect", async {
        Ok(TcpStream::connect(&config.address).await?)
    })
    .await?;
    stream.set_nodelay(true)?;
    let (rd, mut writer) = stream.into_split();
    let mut reader = FrameReader::new(rd);
    let p = Protocol::V2;
    let mut buf = Vec::new();
    let t = config.setup_timeout;

    let mut exchange = async |req: Request, what: &'static str| -> Result<Reply, ClientError> {
        req.encode(p, &mut buf)?;
        writer.write_all(&buf).await?;
        with_timeout(t, what, read_reply(&mut reader, p)).await
    };

    match exchange(Request::ProtocolVersion(2), "protocol version").await? {
        Reply::ProtocolVersion { accepted: true } => {}
        Reply::ProtocolVersion { accepted: false } => return Err(ClientError::ProtocolRefused(2)),
        other => return Err(unexpected(b'V', &other)),
    }
    let version = match exchange(Request::ControllerVersion, "controller version").await? {
        Reply::ControllerVersion(v) => v,
        other => return Err(unexpected(b'v', &other)),
    };
    let output = match exchange(
        Request::SetupOutputs {
            frequency: Some(config.frequency),
            names: config.outputs.clone(),
        },
        "output setup",
    )
    .await?
    {
        Reply::SetupOutputs { recipe_id, slots } => {
            let types = slot_types(&slots).map_err(|(i, slot)| ClientError::VariableRefused {
                name: config.outputs.get(i).cloned().unwrap_or_default(),
                slot,
            })?;
            if recipe_id == Some(0) || types.len() != config.outputs.len() {
                return Err(ClientError::OutputRecipeRefused);
            }
            Recipe::new(recipe_id.unwrap_or(0), config.outputs.clone(), types)
        }
        other => return Err(unexpected(b'O', &other)),
    };
    let mut inputs = Vec::new();
    for names in &config.inputs {
        match exchange(
            Request::SetupInputs {
                names: names.clone(),
            },
            "input setup",
        )
        .await?
        {
            Reply::SetupInputs { recipe_id, slots } => {
                let types =
                    slot_types(&slots).map_err(|(i, slot)| ClientError::VariableRefused {
                        name: names.get(i).cloned().unwrap_or_default(),
                        slot,
                    })?;
                if recipe_id == 0 || types.len() != names.len() {
                    return Err(ClientError::VariableRefused {
                        name: names.join(","),
                        slot: Slot::NotFound,
                    });
                }
                inputs.push(Recipe::new(recipe_id, names.clone(), types));
            }
            other => return Err(unexpected(b'I', &other)),
        }
    }
    match exchange(Request::Start, "start").await? {
        Reply::Start { accepted: true } => {}
        Reply::Start { accepted: false } => return Err(ClientError::StartRefused),
        other => return Err(unexpected(b'S', &other)),
    }
    Ok(Session {
        reader,
        writer,
        output: Arc::new(output),
        inputs,
        version,
    })
}

/// An input write on its way to the link task.
struct InputWrite {
    recipe: usize,
    values: Vec<Value>,
}

/// A connected RTDE client. Dropping it closes the link.
#[derive(Debug)]
pub struct RtdeClient {
    state: watch::Receiver<Option<Arc<OutputState>>>,
    status: watch::Receiver<LinkStatus>,
    writes: mpsc::Sender<InputWrite>,
    version: ControllerVersion,
    input_recipes: Vec<Recipe>,
    counters: Arc<LinkCounters>,
    task: tokio::task::JoinHandle<()>,
}

/// Link health counters.
#[derive(Debug, Default)]
struct LinkCounters {
    stalls: AtomicU64,
    reconnects: AtomicU64,
}

impl Drop for RtdeClient {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl RtdeClient {
    /// Stops the background link now, even while other holders (a heartbeat task) still keep
    /// this client: an owner that is done with the controller closes it so, and the link does
    /// not report the controller's own shutdown as a failure to reconnect from.
    pub fn close(&self) {
        self.task.abort();
    }

    /// Connects, negotiates and starts streaming; the link is then kept up in the background.
    pub async fn connect(config: ClientConfig) -> Result<RtdeClient, ClientError> {
        let session = establish(&config).await?;
        let (state_tx, state) = watch::channel(None);
        let (status_tx, status) = watch::channel(LinkStatus::Streaming);
        let (writes, writes_rx) = mpsc::channel(64);
        let version = session.version;
        let input_recipes = session.inputs.clone();
        let counters = Arc::new(LinkCounters::default());
        let task = tokio::spawn(run_link(
            config,
            session,
            state_tx,
            status_tx,
            writes_rx,
            counters.clone(),
        ));
        Ok(RtdeClient {
            state,
            status,
            writes,
            version,
            input_recipes,
            counters,
            task,
        })
    }

    /// The controller version reported at connection.
    pub fn controller_version(&self) -> ControllerVersion {
        self.version
    }

    /// The newest output state (`None` before the first package).
    pub fn latest(&self) -> Option<Arc<OutputState>> {
        self.state.borrow().clone()
    }

    /// Waits for a package newer than the last one seen through this method's receiver.
    pub async fn next_state(&self, timeout: Duration) -> Result<Arc<OutputState>, ClientError> {
        let mut rx = self.state.clone();
        rx.mark_unchanged();
        tokio::time::timeout(timeout, rx.changed())
            .await
            .map_err(|_| ClientError::Timeout("an output package"))?
            .map_err(|_| ClientError::LinkDown)?;
        rx.borrow().clone().ok_or(ClientError::LinkDown)
    }

    /// A receiver of the newest state, for tasks that wait on updates.
    pub fn subscribe(&self) -> watch::Receiver<Option<Arc<OutputState>>> {
        self.state.clone()
    }

    /// Link health.
    pub fn status(&self) -> LinkStatus {
        self.status.borrow().clone()
    }

    /// Stalls detected so far (no package within the stall timeout).
    pub fn stalls(&self) -> u64 {
        self.counters.stalls.load(Ordering::Relaxed)
    }

    /// Successful reconnections so far.
    pub fn reconnects(&self) -> u64 {
        self.counters.reconnects.load(Ordering::Relaxed)
    }

    /// A receiver of link status changes.
    pub fn subscribe_status(&self) -> watch::Receiver<LinkStatus> {
        self.status.clone()
    }

    /// `robot_mode` of the newest state (when in the output recipe and a known code).
    pub fn robot_mode(&self) -> Option<RobotMode> {
        self.latest()?.robot_mode()
    }

    /// `safety_mode` of the newest state (when in the output recipe and a known code).
    pub fn safety_mode(&self) -> Option<SafetyStatus> {
        self.latest()?.safety_mode()
    }

    /// `runtime_state` of the newest state (when in the output recipe).
    pub fn runtime_state(&self) -> Option<RuntimeState> {
        self.latest()?.runtime_state()
    }

    /// Sends values for input recipe `index` (the order of [`ClientConfig::with_input_recipe`]).
    /// Values are checked against the recipe's types before anything is sent.
    pub async fn send_inputs(&self, index: usize, values: &[Value]) -> Result<(), ClientError> {
        let recipe = self
            .input_recipes
            .get(index)
            .ok_or(ClientError::NoSuchInputRecipe(index))?;
        recipe.encode(values, &mut Vec::new())?;
        if *self.status.borrow() != LinkStatus::Streaming {
            return Err(ClientError::LinkDown);
        }
        self.writes
            .send(InputWrite {
                recipe: index,
                values: values.to_vec(),
            })
            .await
            .map_err(|_| ClientError::LinkDown)
    }
}

enum LinkEnd {
    Stalled,
    Failed(ClientError),
    Closed,
}

async fn stream_session(
    config: &ClientConfig,
    session: &mut Session,
    state_tx: &watch::Sender<Option<Arc<OutputState>>>,
    writes: &mut mpsc::Receiver<InputWrite>,
) -> LinkEnd {
    let mut buf = Vec::with_capacity(256);
    // The stall deadline runs from the last package received: our own writes (a heartbeat every
    // few tens of ms) must not keep a silent controller looking alive.
    let mut last_package = tokio::time::Instant::now();
    loop {
        tokio::select! {
            // Buffered packages are read before the deadline is looked at, so a client that was
            // itself descheduled for a while does not mistake its backlog for silence.
            biased;
            frame = session.reader.next() => {
                let (ty, payload) = match frame {
                    Err(e) => return LinkEnd::Failed(e.into()),
                    Ok(None) => return LinkEnd::Failed(ClientError::Io("controller closed the connection".into())),
                    Ok(Some(frame)) => frame,
                };
                last_package = tokio::time::Instant::now();
                if ty != TYPE_DATA {
                    match Reply::decode(ty, payload, Protocol::V2) {
                        Ok(Reply::Text(t)) => tracing::info!(level = t.level, "controller says: {}", t.message),
                        Ok(other) => tracing::debug!(?other, "ignoring reply while streaming"),
                        Err(e) => return LinkEnd::Failed(e.into()),
                    }
                    continue;
                }
                let Some((&recipe_id, values)) = payload.split_first() else {
                    return LinkEnd::Failed(CodecError::Truncated { ty: 'U', need: 1, got: 0 }.into());
                };
                if recipe_id != session.output.id {
                    tracing::warn!(recipe_id, "data package for an unknown output recipe");
                    continue;
                }
                let mut decoded = Vec::with_capacity(session.output.types.len());
                if let Err(e) = session.output.decode_into(values, &mut decoded) {
                    return LinkEnd::Failed(e.into());
                }
                state_tx.send_replace(Some(Arc::new(OutputState {
                    recipe: session.output.clone(),
                    values: decoded,
                    received_at: Instant::now(),
                })));
            }
            write = writes.recv() => {
                let Some(write) = write else { return LinkEnd::Closed };
                let Some(recipe) = session.inputs.get(write.recipe) else { continue };
                buf.clear();
                buf.extend_from_slice(&[0, 0, TYPE_DATA, recipe.id]);
                if recipe.encode(&write.values, &mut buf).is_err() {
                    continue;
                }
                let size = u16::try_from(buf.len()).unwrap_or(u16::MAX);
                buf[..2].copy_from_slice(&size.to_be_bytes());
                if let Err(e) = session.writer.write_all(&buf).await {
                    return LinkEnd::Failed(e.into());
                }
            }
            () = tokio::time::sleep_until(last_package + config.stall_timeout) => return LinkEnd::Stalled,
        }
    }
}

async fn run_link(
    config: ClientConfig,
    mut session: Session,
    state_tx: watch::Sender<Option<Arc<OutputState>>>,
    status_tx: watch::Sender<LinkStatus>,
    mut writes: mpsc::Receiver<InputWrite>,
    counters: Arc<LinkCounters>,
) {
    loop {
        let end = stream_session(&config, &mut session, &state_tx, &mut writes).await;
        // Close the old connection before dialling again: the controller releases the input
        // registers it holds only when it sees that socket close.
        drop(session);
        match end {
            LinkEnd::Closed => {
                status_tx.send_replace(LinkStatus::Closed);
                return;
            }
            LinkEnd::Stalled => {
                counters.stalls.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(timeout = ?config.stall_timeout, "RTDE stream stalled; reconnecting");
                status_tx.send_replace(LinkStatus::Stalled);
            }
            LinkEnd::Failed(e) => {
                tracing::warn!(error = %e, "RTDE link failed; reconnecting");
                status_tx.send_replace(LinkStatus::Reconnecting(0));
            }
        }
        let mut attempt = 0u32;
        session = loop {
            if config.backoff.max_attempts.is_some_and(|m| attempt >= m) {
                status_tx
                    .send_replace(LinkStatus::Failed(ClientError::GaveUp(attempt).to_string()));
                return;
            }
            tokio::time::sleep(config.backoff.delay(attempt)).await;
            attempt += 1;
            status_tx.send_replace(LinkStatus::Reconnecting(attempt));
            match establish(&config).await {
                Ok(s) => break s,
                Err(e) => tracing::debug!(attempt, error = %e, "RTDE reconnect failed"),
            }
        };
        counters.reconnects.fetch_add(1, Ordering::Relaxed);
        status_tx.send_replace(LinkStatus::Streaming);
    }
}
