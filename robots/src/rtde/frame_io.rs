//! Cancel-safe async reading of RTDE frames and writing of encoded packages.

use super::package::{CodecError, split_frame};
use std::io;
use tokio::io::{AsyncRead, AsyncReadExt};

/// Reads whole frames from a byte stream. `next` is cancel-safe (usable in `select!`): bytes
/// already read stay in the buffer. The buffer never holds more than one maximal frame plus one
/// read, so memory is bounded whatever the peer sends.
#[derive(Debug)]
pub struct FrameReader<R> {
    inner: R,
    buf: Vec<u8>,
    start: usize,
    consumed: usize,
}

impl<R: AsyncRead + Unpin> FrameReader<R> {
    /// Wraps a reader.
    pub fn new(inner: R) -> FrameReader<R> {
        FrameReader {
            inner,
            buf: Vec::with_capacity(8192),
            start: 0,
            consumed: 0,
        }
    }

    /// The next frame as (type byte, payload); `Ok(None)` at a clean end of stream.
    /// A size field below 3 is `InvalidData` (the stream cannot be resynchronised).
    pub async fn next(&mut self) -> io::Result<Option<(u8, &[u8])>> {
        self.start += std::mem::take(&mut self.consumed);
        loop {
            match split_frame(&self.buf[self.start..]) {
                Err(e) => return Err(io::Error::new(io::ErrorKind::InvalidData, e)),
                Ok(Some((_, _, len))) => {
                    self.consumed = len;
                    let frame = &self.buf[self.start..self.start + len];
                    return Ok(Some((frame[2], &frame[3..])));
                }
                Ok(None) => {}
            }
            if self.start > 0 {
                self.buf.drain(..self.start);
                self.start = 0;
            }
            self.buf.reserve(4096);
            let n = self.inner.read_buf(&mut self.buf).await?;
            if n == 0 {
                return if self.buf.is_empty() {
                    Ok(None)
                } else {
                    Err(io::Error::new(
                        io::ErrorKind::UnexpectedEof,
                        "stream ended inside a package",
                    ))
                };
            }
        }
    }

    /// The wrapped reader.
    pub fn get_mut(&mut self) -> &mut R {
        &mut self.inner
    }
}

/// Turns a codec error into an `InvalidData` I/O error.
pub fn invalid(e: CodecError) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, e)
}
