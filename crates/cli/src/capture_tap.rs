//! Recording bus events into capture files (pcap, pcapng, candump) from a bus tap; which
//! events become which records is [`cantwin_capture::bus_tap`]'s.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result};
use cantwin_bus::{BusEvent, BusInfo, Simulation, Tap};
use cantwin_capture::{CaptureWriter, Format, Record};

/// A capture writer shared by the taps of several buses.
pub type SharedWriter = Arc<Mutex<Box<dyn CaptureWriter + Send>>>;

/// A tap writing every event of its bus into a capture.
pub struct CaptureTap {
    writer: SharedWriter,
    failed: Arc<Mutex<Option<String>>>,
}

impl CaptureTap {
    fn record(&mut self, record: Record) {
        let Ok(mut w) = self.writer.lock() else {
            return;
        };
        if let Err(e) = w.write_record(&record)
            && let Ok(mut failed) = self.failed.lock()
            && failed.is_none()
        {
            *failed = Some(e.to_string());
        }
    }
}

impl Tap for CaptureTap {
    fn on_event(&mut self, bus: &BusInfo<'_>, event: &BusEvent) {
        if let Some(record) = cantwin_capture::bus_tap::record_of(bus, event) {
            self.record(record);
        }
    }
}

/// Open captures on the buses of a simulation.
pub struct Captures {
    writers: Vec<(PathBuf, SharedWriter)>,
    failed: Arc<Mutex<Option<String>>>,
}

impl Captures {
    /// No captures.
    pub fn new() -> Self {
        Captures {
            writers: Vec::new(),
            failed: Arc::new(Mutex::new(None)),
        }
    }

    /// Record every bus of `sim` into `path` in `format`. Classic pcap has no channel field,
    /// so with several buses it writes one file per bus, named `STEM-BUS.EXT`. Returns the
    /// files written.
    pub fn add(
        &mut self,
        sim: &mut Simulation,
        path: &Path,
        format: Format,
    ) -> Result<Vec<PathBuf>> {
        let buses: Vec<(cantwin_bus::BusId, String)> = sim
            .buses()
            .iter()
            .map(|b| (b.id(), b.name().to_string()))
            .collect();
        let is_pcap = format == Format::Pcap;
        let plan: Vec<(PathBuf, Vec<cantwin_bus::BusId>)> = if is_pcap && buses.len() > 1 {
            let stem = path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            buses
                .iter()
                .map(|(id, name)| {
                    let ext = path
                        .extension()
                        .map(|e| e.to_string_lossy().into_owned())
                        .unwrap_or_else(|| "pcap".into());
                    (
                        path.with_file_name(format!("{stem}-{name}.{ext}")),
                        vec![*id],
                    )
                })
                .collect()
        } else {
            vec![(
                path.to_path_buf(),
                buses.iter().map(|(id, _)| *id).collect(),
            )]
        };
        let mut files = Vec::new();
        for (file, ids) in plan {
            let out = std::fs::File::create(&file)
                .with_context(|| format!("creating capture {}", file.display()))?;
            let writer: SharedWriter = Arc::new(Mutex::new(
                cantwin_capture::writer(format, std::io::BufWriter::new(out))
                    .with_context(|| format!("creating capture {}", file.display()))?,
            ));
            for id in ids {
                if let Some(bus) = sim.bus_mut(id) {
                    bus.add_tap(CaptureTap {
                        writer: writer.clone(),
                        failed: self.failed.clone(),
                    });
                }
            }
            self.writers.push((file.clone(), writer));
            files.push(file);
        }
        Ok(files)
    }

    /// Flush every capture; an error met while recording is reported here.
    pub fn finish(&self) -> Result<()> {
        for (file, w) in &self.writers {
            let mut w = w
                .lock()
                .map_err(|_| anyhow::anyhow!("capture {} poisoned", file.display()))?;
            w.flush()
                .with_context(|| format!("writing capture {}", file.display()))?;
        }
        if let Ok(failed) = self.failed.lock()
            && let Some(e) = failed.as_ref()
        {
            anyhow::bail!("writing a capture failed: {e}");
        }
        Ok(())
    }
}
