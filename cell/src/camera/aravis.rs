//! A GenICam camera through libaravis 0.8 (`--camera aravis:` for the first camera found, or
//! `aravis:DEVICE` with an Aravis device id or the camera's IP address); cargo feature `aravis`.
//!
//! Aravis objects may not leave the thread that made them, so one worker thread owns the camera
//! and answers capture requests over a channel. Each capture acquires one frame in single-frame
//! mode, started after the request, so the picture is never older than the request. A camera
//! that stops answering (unplugged, powered off, network down) gives [`CameraError::Vanished`].

use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::time::{Duration, Instant, SystemTime};

use aravis::glib;
use aravis::prelude::*;
use aravis::{AcquisitionMode, Buffer, BufferStatus, Camera, PixelFormat};
use image::{DynamicImage, ImageBuffer};
use perception::FrameImage;

use super::{CameraError, CameraSource, Capture, Sensor, check_image};

/// How long opening a camera may take.
const OPEN_TIMEOUT: Duration = Duration::from_secs(10);

/// How much longer than the capture deadline the worker may take to answer (starting and
/// stopping the acquisition) before the camera counts as gone.
const ANSWER_MARGIN: Duration = Duration::from_secs(3);

/// A frame from the worker: pixels and when the acquisition ended.
type Frame = Result<(DynamicImage, SystemTime), CameraError>;

/// A GenICam camera, served by a worker thread.
pub struct AravisCamera {
    name: String,
    sensor: Sensor,
    requests: Option<Sender<(u64, Duration)>>,
    frames: Receiver<(u64, Frame)>,
    worker: Option<std::thread::JoinHandle<()>>,
    next: u64,
    gone: Option<String>,
}

impl AravisCamera {
    /// Opens `device` (the first camera found when `None`) for images of `sensor`'s size.
    pub fn open(device: Option<&str>, sensor: Sensor) -> Result<Self, CameraError> {
        let name = format!("GenICam camera {}", device.unwrap_or("(first found)"));
        let (req_tx, req_rx) = channel::<(u64, Duration)>();
        let (frame_tx, frame_rx) = channel::<(u64, Frame)>();
        let (open_tx, open_rx) = channel::<Result<String, CameraError>>();
        let device = device.map(str::to_string);
        let worker_name = name.clone();
        let worker = std::thread::Builder::new()
            .name("aravis-camera".into())
            .spawn(move || {
                let camera = match Camera::new(device.as_deref()) {
                    Ok(c) => c,
                    Err(e) => {
                        let _ = open_tx.send(Err(CameraError::Vanished {
                            source_name: worker_name,
                            reason: format!("cannot open it: {e}"),
                        }));
                        return;
                    }
                };
                let described = format!(
                    "GenICam camera {} {} ({})",
                    camera
                        .vendor_name()
                        .map(|s| s.to_string())
                        .unwrap_or_default(),
                    camera
                        .model_name()
                        .map(|s| s.to_string())
                        .unwrap_or_default(),
                    camera
                        .device_id()
                        .map(|s| s.to_string())
                        .unwrap_or_else(|_| device.clone().unwrap_or_default()),
                );
                if open_tx.send(Ok(described.clone())).is_err() {
                    return;
                }
                while let Ok((id, deadline)) = req_rx.recv() {
                    let frame = grab(&camera, &described, deadline);
                    if frame_tx.send((id, frame)).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| CameraError::Vanished {
                source_name: name.clone(),
                reason: format!("cannot start its worker thread: {e}"),
            })?;
        let described = match open_rx.recv_timeout(OPEN_TIMEOUT) {
            Ok(r) => r?,
            Err(_) => {
                return Err(CameraError::Vanished {
                    source_name: name,
                    reason: format!("it did not open within {} s", OPEN_TIMEOUT.as_secs_f64()),
                });
            }
        };
        Ok(Self {
            name: described,
            sensor,
            requests: Some(req_tx),
            frames: frame_rx,
            worker: Some(worker),
            next: 0,
            gone: None,
        })
    }

    fn vanished(&mut self, reason: String) -> CameraError {
        self.gone = Some(reason.clone());
        CameraError::Vanished {
            source_name: self.name.clone(),
            reason,
        }
    }
}

impl CameraSource for AravisCamera {
    fn capture(&mut self, deadline: Duration) -> Result<Capture, CameraError> {
        if let Some(reason) = &self.gone {
            return Err(CameraError::Vanished {
                source_name: self.name.clone(),
                reason: reason.clone(),
            });
        }
        self.next += 1;
        let id = self.next;
        let sent = self
            .requests
            .as_ref()
            .is_some_and(|r| r.send((id, deadline)).is_ok());
        if !sent {
            return Err(self.vanished("its worker stopped".into()));
        }
        let start = Instant::now();
        loop {
            let left = (deadline + ANSWER_MARGIN).saturating_sub(start.elapsed());
            match self.frames.recv_timeout(left) {
                // A late answer to an earlier request is dropped.
                Ok((got, _)) if got != id => continue,
                Ok((_, Ok((pixels, taken)))) => {
                    let pixels = check_image(pixels, self.sensor, &self.name)?;
                    return Ok(Capture {
                        image: FrameImage::full(pixels),
                        path: None,
                        taken,
                    });
                }
                Ok((_, Err(e @ CameraError::Vanished { .. }))) => {
                    if let CameraError::Vanished { reason, .. } = &e {
                        self.gone = Some(reason.clone());
                    }
                    return Err(e);
                }
                Ok((_, Err(e))) => return Err(e),
                Err(RecvTimeoutError::Timeout) => {
                    return Err(self.vanished(format!(
                        "it did not answer within {:.3} s",
                        (deadline + ANSWER_MARGIN).as_secs_f64()
                    )));
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(self.vanished("its worker stopped".into()));
                }
            }
        }
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}

impl Drop for AravisCamera {
    fn drop(&mut self) {
        // Closing the request channel ends the worker once its grab returns.
        self.requests = None;
        if let Some(w) = self.worker.take() {
            // A worker stuck in a dead camera's call is left to finish on its own.
            if w.is_finished() {
                let _ = w.join();
            }
        }
    }
}

/// Acquires one frame in single-frame mode within `deadline`.
fn grab(camera: &Camera, name: &str, deadline: Duration) -> Frame {
    let gone = |what: &str, e: glib::Error| CameraError::Vanished {
        source_name: name.into(),
        reason: format!("{what}: {e}"),
    };
    let payload = camera
        .payload()
        .map_err(|e| gone("reading the payload size", e))?;
    let stream = camera
        .create_stream()
        .map_err(|e| gone("opening the image stream", e))?;
    stream.push_buffer(Buffer::new_allocate(payload as usize));
    camera
        .set_acquisition_mode(AcquisitionMode::SingleFrame)
        .map_err(|e| gone("setting single-frame mode", e))?;
    camera
        .start_acquisition()
        .map_err(|e| gone("starting the acquisition", e))?;
    let micros = u64::try_from(deadline.as_micros())
        .unwrap_or(u64::MAX)
        .max(1);
    let buffer = stream.timeout_pop_buffer(micros);
    let stopped = camera.stop_acquisition();
    let taken = SystemTime::now();
    let Some(buffer) = buffer else {
        // No frame and the camera no longer answers its control channel: it is gone.
        stopped.map_err(|e| gone("stopping the acquisition", e))?;
        return Err(CameraError::Timeout {
            source_name: name.into(),
            waited: deadline,
        });
    };
    if buffer.status() != BufferStatus::Success {
        stopped.map_err(|e| gone("stopping the acquisition", e))?;
        return Err(CameraError::Timeout {
            source_name: format!("{name} (incomplete frame: {:?})", buffer.status()),
            waited: deadline,
        });
    }
    Ok((to_image(&buffer, name)?, taken))
}

/// The buffer's pixels as an image: Mono8, Mono16, RGB8 (packed).
fn to_image(buffer: &Buffer, name: &str) -> Result<DynamicImage, CameraError> {
    let (w, h) = (buffer.image_width(), buffer.image_height());
    let format = buffer.image_pixel_format();
    let unsupported = |what: String| CameraError::UnsupportedFormat {
        what: name.into(),
        format: what,
    };
    let (w, h) = match (u32::try_from(w), u32::try_from(h)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => return Err(unsupported(format!("a {w} × {h} frame"))),
    };
    let data = buffer.image_data();
    let n = w as usize * h as usize;
    let bad_len = |bytes_per_pixel: usize| {
        unsupported(format!(
            "a {}-byte frame for {w} × {h} pixels of {bytes_per_pixel} bytes",
            data.len()
        ))
    };
    Ok(if format == PixelFormat::MONO_8 {
        if data.len() < n {
            return Err(bad_len(1));
        }
        DynamicImage::ImageLuma8(
            ImageBuffer::from_raw(w, h, data[..n].to_vec()).ok_or_else(|| bad_len(1))?,
        )
    } else if format == PixelFormat::MONO_16 {
        if data.len() < 2 * n {
            return Err(bad_len(2));
        }
        // GenICam pixel data is little-endian.
        let px: Vec<u16> = data[..2 * n]
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        DynamicImage::ImageLuma16(ImageBuffer::from_raw(w, h, px).ok_or_else(|| bad_len(2))?)
    } else if format == PixelFormat::RGB_8_PACKED {
        if data.len() < 3 * n {
            return Err(bad_len(3));
        }
        DynamicImage::ImageRgb8(
            ImageBuffer::from_raw(w, h, data[..3 * n].to_vec()).ok_or_else(|| bad_len(3))?,
        )
    } else {
        return Err(unsupported(format!(
            "pixel format 0x{:08x} (set the camera to Mono8, Mono16 or RGB8)",
            format.raw()
        )));
    })
}
