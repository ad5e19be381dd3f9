//! PNG output as a frame sink: selected frames are copied and encoded on a worker thread, so
//! encoding never stalls the render loop.

use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use crossbeam_channel::{Sender, bounded};

use crate::error::{Error, Result};
use crate::readback::{FrameSink, FrameView, OwnedFrame};

/// Encodes RGBA8 pixels as a PNG file (atomically).
pub fn write_png(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image_checked(rgba, width, height)
        .map_err(|e| Error::invalid("PNG encoding", e.to_string()))?;
    super::write_atomic(path, &bytes)
}

trait WriteChecked {
    fn write_image_checked(self, rgba: &[u8], w: u32, h: u32) -> Result<(), image::ImageError>;
}

impl<W: std::io::Write> WriteChecked for image::codecs::png::PngEncoder<W> {
    fn write_image_checked(self, rgba: &[u8], w: u32, h: u32) -> Result<(), image::ImageError> {
        use image::ImageEncoder;
        self.write_image(rgba, w, h, image::ExtendedColorType::Rgba8)
    }
}

/// Writes the frames whose index is in `frames` to `dir/frame_NNNNN.png`.
pub struct PngSink {
    frames: Vec<u64>,
    sender: Option<Sender<OwnedFrame>>,
    worker: Option<JoinHandle<Result<Vec<PathBuf>>>>,
}

impl PngSink {
    pub fn new(dir: &Path, frames: Vec<u64>) -> Self {
        let (sender, receiver) = bounded::<OwnedFrame>(2);
        let dir = dir.to_path_buf();
        let worker = std::thread::spawn(move || {
            let mut written = Vec::new();
            for frame in receiver {
                let path = dir.join(format!("frame_{:05}.png", frame.index));
                write_png(&path, frame.width, frame.height, &frame.rgba)?;
                written.push(path);
            }
            Ok(written)
        });
        PngSink {
            frames,
            sender: Some(sender),
            worker: Some(worker),
        }
    }

    /// Waits for the writer; returns the files written.
    pub fn finish(mut self) -> Result<Vec<PathBuf>> {
        self.sender.take();
        match self.worker.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(Error::invalid("PNG writer", "worker thread panicked")),
            None => Ok(Vec::new()),
        }
    }
}

impl FrameSink for PngSink {
    fn frame(&mut self, frame: &FrameView<'_>) -> Result<()> {
        if self.frames.contains(&frame.index)
            && let Some(sender) = &self.sender
        {
            // A send fails only if the worker stopped on an error; `finish` reports it.
            let _ = sender.send(OwnedFrame::copy_of(frame));
        }
        Ok(())
    }
}

impl Drop for PngSink {
    fn drop(&mut self) {
        self.sender.take();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}
