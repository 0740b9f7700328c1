//! The script port (30003): receives URScript text and hands complete programs to the controller.

use super::controller::VirtualController;
use std::io;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::AsyncReadExt;
use tokio::net::{TcpListener, TcpStream};

/// Largest script accepted in one upload.
pub const MAX_SCRIPT: usize = 1 << 20;
/// A pause this long after data ends an upload when the sender keeps the socket open.
pub const IDLE_GAP: Duration = Duration::from_millis(50);

/// Serves the script port until the task is aborted.
pub async fn serve(listener: TcpListener, controller: Arc<VirtualController>) -> io::Result<()> {
    loop {
        let (stream, _) = listener.accept().await?;
        let controller = controller.clone();
        tokio::spawn(async move {
            if let Err(e) = serve_one(stream, controller).await {
                tracing::debug!(error = %e, "script connection ended");
            }
        });
    }
}

async fn serve_one(mut stream: TcpStream, controller: Arc<VirtualController>) -> io::Result<()> {
    let mut buf = Vec::new();
    let mut chunk = vec![0u8; 16 * 1024];
    loop {
        let read = if buf.is_empty() {
            stream.read(&mut chunk).await.map(Some)
        } else {
            match tokio::time::timeout(IDLE_GAP, stream.read(&mut chunk)).await {
                Ok(r) => r.map(Some),
                Err(_) => Ok(None),
            }
        }?;
        match read {
            Some(0) => {
                deliver(&controller, &buf);
                return Ok(());
            }
            Some(n) => {
                if buf.len() + n > MAX_SCRIPT {
                    tracing::warn!("script over {MAX_SCRIPT} bytes refused");
                    return Err(io::Error::new(
                        io::ErrorKind::InvalidData,
                        "script too large",
                    ));
                }
                buf.extend_from_slice(&chunk[..n]);
            }
            None => {
                deliver(&controller, &buf);
                buf.clear();
            }
        }
    }
}

fn deliver(controller: &VirtualController, bytes: &[u8]) {
    if bytes.is_empty() {
        return;
    }
    let text = String::from_utf8_lossy(bytes);
    match controller.upload_script(&text) {
        Ok(()) => {}
        Err(e) => tracing::warn!(error = %e, "script not started"),
    }
}
