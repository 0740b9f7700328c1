//! The UR dashboard server protocol (port 29999): one ASCII command line, one reply line.
//! A typed client, and a line server used by the virtual controller.

use crate::robot::{RobotMode, SafetyStatus};
use std::io;
use std::sync::Arc;
use std::time::Duration;
use thiserror::Error;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::{TcpListener, TcpStream};

/// Default dashboard port.
pub const DASHBOARD_PORT: u16 = 29999;
/// Greeting line a dashboard server sends on connect.
pub const GREETING: &str = "Connected: Universal Robots Dashboard Server";
/// Longest command or reply line accepted.
pub const MAX_LINE: usize = 4096;

/// Errors of the dashboard client.
#[derive(Debug, Error)]
pub enum DashboardError {
    /// Socket error.
    #[error("dashboard I/O error: {0}")]
    Io(#[from] io::Error),
    /// No reply within the timeout.
    #[error("dashboard did not answer {0:?} in time")]
    Timeout(String),
    /// The server did not greet like a UR dashboard.
    #[error("unexpected dashboard greeting {0:?}")]
    BadGreeting(String),
    /// The server closed the connection.
    #[error("dashboard closed the connection")]
    Closed,
    /// The controller answered that it did not do it.
    #[error("dashboard refused {command:?}: {reply}")]
    Refused {
        /// The command.
        command: String,
        /// The reply line.
        reply: String,
    },
    /// A reply could not be parsed.
    #[error("unexpected dashboard reply to {command:?}: {reply}")]
    UnexpectedReply {
        /// The command.
        command: String,
        /// The reply line.
        reply: String,
    },
}

/// The dashboard's word for a robot mode (the `robotmode` reply: `Robotmode: WORD`).
pub fn robot_mode_word(mode: RobotMode) -> &'static str {
    match mode {
        RobotMode::NoController => "NO_CONTROLLER",
        RobotMode::Disconnected => "DISCONNECTED",
        RobotMode::ConfirmSafety => "CONFIRM_SAFETY",
        RobotMode::Booting => "BOOTING",
        RobotMode::PowerOff => "POWER_OFF",
        RobotMode::PowerOn => "POWER_ON",
        RobotMode::Idle => "IDLE",
        RobotMode::Backdrive => "BACKDRIVE",
        RobotMode::Running => "RUNNING",
        RobotMode::UpdatingFirmware => "UPDATING_FIRMWARE",
    }
}

/// The robot mode a dashboard word names; `None` for a word this crate does not know.
pub fn parse_robot_mode(word: &str) -> Option<RobotMode> {
    (-1..=8)
        .filter_map(RobotMode::from_ur_code)
        .find(|m| robot_mode_word(*m) == word)
}

/// The dashboard's word for a safety status (the `safetystatus` reply: `Safetystatus: WORD`).
pub fn safety_status_word(safety: SafetyStatus) -> &'static str {
    match safety {
        SafetyStatus::Normal => "NORMAL",
        SafetyStatus::Reduced => "REDUCED",
        SafetyStatus::ProtectiveStop => "PROTECTIVE_STOP",
        SafetyStatus::Recovery => "RECOVERY",
        SafetyStatus::SafeguardStop => "SAFEGUARD_STOP",
        SafetyStatus::SystemEmergencyStop => "SYSTEM_EMERGENCY_STOP",
        SafetyStatus::RobotEmergencyStop => "ROBOT_EMERGENCY_STOP",
        SafetyStatus::Violation => "VIOLATION",
        SafetyStatus::Fault => "FAULT",
    }
}

/// The safety status a dashboard word names; `None` for a word this crate does not know.
pub fn parse_safety_status(word: &str) -> Option<SafetyStatus> {
    (1..=9)
        .filter_map(SafetyStatus::from_ur_code)
        .find(|s| safety_status_word(*s) == word)
}

/// A connection to the dashboard server.
#[derive(Debug)]
pub struct DashboardClient {
    stream: BufReader<TcpStream>,
    timeout: Duration,
}

impl DashboardClient {
    /// Connects and reads the greeting.
    pub async fn connect(
        address: &str,
        timeout: Duration,
    ) -> Result<DashboardClient, DashboardError> {
        let stream = tokio::time::timeout(timeout, TcpStream::connect(address))
            .await
            .map_err(|_| DashboardError::Timeout("connect".into()))??;
        stream.set_nodelay(true)?;
        let mut client = DashboardClient {
            stream: BufReader::new(stream),
            timeout,
        };
        let greeting = client.read_line("greeting").await?;
        if !greeting.starts_with("Connected: Universal Robots Dashboard Server") {
            return Err(DashboardError::BadGreeting(greeting));
        }
        Ok(client)
    }

    async fn read_line(&mut self, what: &str) -> Result<String, DashboardError> {
        let mut line = Vec::new();
        let mut limited = (&mut self.stream).take(MAX_LINE as u64);
        let read = limited.read_until(b'\n', &mut line);
        let n = tokio::time::timeout(self.timeout, read)
            .await
            .map_err(|_| DashboardError::Timeout(what.into()))??;
        if n == 0 {
            return Err(DashboardError::Closed);
        }
        Ok(String::from_utf8_lossy(&line).trim().to_owned())
    }

    /// Sends one command line and returns the reply line.
    pub async fn command(&mut self, command: &str) -> Result<String, DashboardError> {
        let mut line = command.trim().to_owned();
        line.push('\n');
        self.stream.get_mut().write_all(line.as_bytes()).await?;
        self.read_line(command).await
    }

    async fn expect(&mut self, command: &str, ok: &[&str]) -> Result<String, DashboardError> {
        let reply = self.command(command).await?;
        if ok.iter().any(|w| reply.starts_with(w)) {
            Ok(reply)
        } else {
            Err(DashboardError::Refused {
                command: command.into(),
                reply,
            })
        }
    }

    /// `power on`.
    pub async fn power_on(&mut self) -> Result<(), DashboardError> {
        self.expect("power on", &["Powering on"]).await.map(drop)
    }

    /// `power off`.
    pub async fn power_off(&mut self) -> Result<(), DashboardError> {
        self.expect("power off", &["Powering off"]).await.map(drop)
    }

    /// `brake release`.
    pub async fn brake_release(&mut self) -> Result<(), DashboardError> {
        self.expect("brake release", &["Brake releasing"])
            .await
            .map(drop)
    }

    /// `play`.
    pub async fn play(&mut self) -> Result<(), DashboardError> {
        self.expect("play", &["Starting program"]).await.map(drop)
    }

    /// `stop`.
    pub async fn stop(&mut self) -> Result<(), DashboardError> {
        self.expect("stop", &["Stopped"]).await.map(drop)
    }

    /// `pause`.
    pub async fn pause(&mut self) -> Result<(), DashboardError> {
        self.expect("pause", &["Pausing program"]).await.map(drop)
    }

    /// `unlock protective stop` (a real UR refuses it during the first 5 s).
    pub async fn unlock_protective_stop(&mut self) -> Result<(), DashboardError> {
        self.expect("unlock protective stop", &["Protective stop releasing"])
            .await
            .map(drop)
    }

    /// `close safety popup`.
    pub async fn close_safety_popup(&mut self) -> Result<(), DashboardError> {
        self.expect("close safety popup", &["closing safety popup"])
            .await
            .map(drop)
    }

    /// `load PROGRAM`.
    pub async fn load(&mut self, program: &str) -> Result<(), DashboardError> {
        if program.contains(['\n', '\r']) {
            return Err(DashboardError::Refused {
                command: "load".into(),
                reply: "program name contains a line break".into(),
            });
        }
        self.expect(&format!("load {program}"), &["Loading program"])
            .await
            .map(drop)
    }

    /// `robotmode`; a mode word this crate does not know is an
    /// [`DashboardError::UnexpectedReply`].
    pub async fn robot_mode(&mut self) -> Result<RobotMode, DashboardError> {
        let reply = self.command("robotmode").await?;
        reply
            .strip_prefix("Robotmode: ")
            .and_then(|m| parse_robot_mode(m.trim()))
            .ok_or(DashboardError::UnexpectedReply {
                command: "robotmode".into(),
                reply,
            })
    }

    /// `safetystatus`; a status word this crate does not know is an
    /// [`DashboardError::UnexpectedReply`].
    pub async fn safety_status(&mut self) -> Result<SafetyStatus, DashboardError> {
        let reply = self.command("safetystatus").await?;
        reply
            .strip_prefix("Safetystatus: ")
            .and_then(|m| parse_safety_status(m.trim()))
            .ok_or(DashboardError::UnexpectedReply {
                command: "safetystatus".into(),
                reply,
            })
    }

    /// `PolyscopeVersion`.
    pub async fn polyscope_version(&mut self) -> Result<String, DashboardError> {
        self.command("PolyscopeVersion").await
    }
}

/// Serves the dashboard protocol on `listener`: greets, then answers each line with `handler`.
/// Over-long lines are answered as not understood and discarded; `quit` closes the connection.
pub async fn serve(
    listener: TcpListener,
    handler: Arc<dyn Fn(&str) -> String + Send + Sync>,
) -> io::Result<()> {
    loop {
        let (stream, _) = listener.accept().await?;
        let handler = handler.clone();
        tokio::spawn(async move {
            if let Err(e) = serve_one(stream, handler).await {
                tracing::debug!(error = %e, "dashboard connection ended");
            }
        });
    }
}

async fn serve_one(
    stream: TcpStream,
    handler: Arc<dyn Fn(&str) -> String + Send + Sync>,
) -> io::Result<()> {
    stream.set_nodelay(true)?;
    let mut stream = BufReader::new(stream);
    stream
        .get_mut()
        .write_all(format!("{GREETING}\n").as_bytes())
        .await?;
    let mut line = Vec::new();
    loop {
        line.clear();
        let n = (&mut stream)
            .take(MAX_LINE as u64)
            .read_until(b'\n', &mut line)
            .await?;
        if n == 0 {
            return Ok(());
        }
        let reply = if line.last() != Some(&b'\n') && n == MAX_LINE {
            // Discard the rest of the over-long line.
            let mut rest = Vec::new();
            loop {
                rest.clear();
                let m = (&mut stream)
                    .take(MAX_LINE as u64)
                    .read_until(b'\n', &mut rest)
                    .await?;
                if m == 0 || rest.last() == Some(&b'\n') {
                    break;
                }
            }
            "could not understand: line too long".to_owned()
        } else {
            let text = String::from_utf8_lossy(&line);
            let text = text.trim();
            if text.is_empty() {
                continue;
            }
            let reply = handler(text);
            if text.eq_ignore_ascii_case("quit") {
                stream
                    .get_mut()
                    .write_all(format!("{reply}\n").as_bytes())
                    .await?;
                return Ok(());
            }
            reply
        };
        stream
            .get_mut()
            .write_all(format!("{reply}\n").as_bytes())
            .await?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dashboard_words_round_trip() {
        for code in -1..=8 {
            let mode = RobotMode::from_ur_code(code).unwrap();
            assert_eq!(parse_robot_mode(robot_mode_word(mode)), Some(mode));
        }
        for code in 1..=9 {
            let safety = SafetyStatus::from_ur_code(code).unwrap();
            assert_eq!(
                parse_safety_status(safety_status_word(safety)),
                Some(safety)
            );
        }
        assert_eq!(robot_mode_word(RobotMode::PowerOff), "POWER_OFF");
        assert_eq!(
            safety_status_word(SafetyStatus::ProtectiveStop),
            "PROTECTIVE_STOP"
        );
        for word in ["UNKNOWN", "running", "", "AUTOMATIC_MODE_SAFEGUARD_STOP"] {
            assert_eq!(parse_robot_mode(word), None, "{word}");
            assert_eq!(parse_safety_status(word), None, "{word}");
        }
    }
}
