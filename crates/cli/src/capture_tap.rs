//! Recording bus events into capture files (pcap, pcapng, candump) from a bus tap.
//!
//! Frames are stamped at the end of their EOF, when receivers take them, in wall time when the
//! simulation is paced (its time map) and in bus time since the Unix epoch in virtual time, so
//! two runs of the same scenario give byte-identical captures. Error frames and controller
//! events are recorded as SocketCAN error frames (`linux/can/error.h` classes), as
//! `candump -e` shows them.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result};
use cantwin_bus::{BusEvent, BusInfo, ErrorKind, Simulation, Tap};
use cantwin_can::{ControllerEvent, Instant};
use cantwin_capture::{CaptureWriter, ErrorFrame, Event, Format, Record, error_class};

/// A capture writer shared by the taps of several buses.
pub type SharedWriter = Arc<Mutex<Box<dyn CaptureWriter + Send>>>;

/// A tap writing every event of its bus into a capture.
pub struct CaptureTap {
    writer: SharedWriter,
    failed: Arc<Mutex<Option<String>>>,
}

// SocketCAN error frame details (linux/can/error.h): data[1] controller status, data[2]
// protocol error type, data[3] protocol error location.
const CRTL_RX_OVERFLOW: u8 = 0x01;
const CRTL_TX_OVERFLOW: u8 = 0x02;
const CRTL_RX_PASSIVE: u8 = 0x10;
const CRTL_TX_PASSIVE: u8 = 0x20;
const CRTL_ACTIVE: u8 = 0x40;
const PROT_BIT: u8 = 0x01;
const PROT_FORM: u8 = 0x02;
const PROT_STUFF: u8 = 0x04;
const LOC_ID28_21: u8 = 0x02;
const LOC_CRC_SEQ: u8 = 0x08;
const LOC_ACK: u8 = 0x19;

fn error_frame(class: u32, data: [u8; 8]) -> Option<ErrorFrame> {
    ErrorFrame::new(class, data).ok()
}

fn stamp(bus: &BusInfo<'_>, at: Instant) -> u64 {
    match bus.time_map {
        Some(map) => u64::try_from(map.unix_nanos(at)).unwrap_or(u64::MAX),
        None => at.as_nanos(),
    }
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
        let (at, ev) = match *event {
            BusEvent::Frame(f) if f.dropped => return,
            BusEvent::Frame(f) => (f.end, Some(Event::from(f.frame))),
            BusEvent::Error(r) => {
                let (class, data) = match r.kind {
                    ErrorKind::Ack => (
                        error_class::NO_ACK | error_class::PROTOCOL,
                        [0, 0, 0, LOC_ACK, 0, 0, 0, 0],
                    ),
                    ErrorKind::Corrupted => (
                        error_class::PROTOCOL | error_class::BUS_ERROR,
                        [0, 0, PROT_BIT, LOC_CRC_SEQ, 0, 0, 0, 0],
                    ),
                    ErrorKind::BitRateMismatch => (
                        error_class::PROTOCOL | error_class::BUS_ERROR,
                        [0, 0, PROT_STUFF, LOC_ID28_21, 0, 0, 0, 0],
                    ),
                    ErrorKind::Aborted => (
                        error_class::PROTOCOL | error_class::BUS_ERROR,
                        [0, 0, PROT_FORM, 0, 0, 0, 0, 0],
                    ),
                };
                (r.detected, error_frame(class, data).map(Into::into))
            }
            BusEvent::Controller { event, at, .. } => {
                let (class, ctrl) = match event {
                    ControllerEvent::BusOff => (error_class::BUS_OFF, 0),
                    ControllerEvent::BusOffRecovered => (error_class::RESTARTED, 0),
                    ControllerEvent::ErrorPassive => {
                        (error_class::CONTROLLER, CRTL_RX_PASSIVE | CRTL_TX_PASSIVE)
                    }
                    ControllerEvent::ErrorActive => (error_class::CONTROLLER, CRTL_ACTIVE),
                    ControllerEvent::RxOverrun => (error_class::CONTROLLER, CRTL_RX_OVERFLOW),
                    ControllerEvent::TxDropped => (error_class::CONTROLLER, CRTL_TX_OVERFLOW),
                };
                (
                    at,
                    error_frame(class, [0, ctrl, 0, 0, 0, 0, 0, 0]).map(Into::into),
                )
            }
        };
        if let Some(ev) = ev {
            self.record(Record::new(stamp(bus, at), bus.name, ev));
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
