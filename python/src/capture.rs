//! `cantwin.Capture`: recording buses into pcap, pcapng or candump files.

use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};

use cantwin_bus::{BusEvent, BusInfo, Tap};
use cantwin_capture::{CaptureWriter, Format};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::core::{Shared, err};

/// A writer shared by the taps of the buses it records; `None` once closed.
pub(crate) type SharedWriter = Arc<Mutex<Option<Box<dyn CaptureWriter + Send>>>>;

/// The tap on a bus: every frame, error frame and controller event, as
/// `cantwin sim --capture` records them ([`cantwin_capture::bus_tap`]).
struct CaptureTap {
    writer: SharedWriter,
    failed: Arc<Mutex<Option<String>>>,
}

impl Tap for CaptureTap {
    fn on_event(&mut self, bus: &BusInfo<'_>, event: &BusEvent) {
        let Some(record) = cantwin_capture::bus_tap::record_of(bus, event) else {
            return;
        };
        let mut w = self.writer.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(w) = w.as_mut()
            && let Err(e) = w.write_record(&record)
        {
            let mut failed = self.failed.lock().unwrap_or_else(PoisonError::into_inner);
            failed.get_or_insert_with(|| e.to_string());
        }
    }
}

/// A capture file being written (from :py:meth:`Simulation.capture`). Close it, or use it
/// as a context manager, to complete the file.
#[pyclass(module = "cantwin._native", frozen)]
pub struct Capture {
    writer: SharedWriter,
    failed: Arc<Mutex<Option<String>>>,
    path: PathBuf,
}

fn format_of(path: &std::path::Path, format: Option<&str>) -> PyResult<Format> {
    match format {
        Some("pcap") => Ok(Format::Pcap),
        Some("pcapng") => Ok(Format::Pcapng),
        Some("candump") => Ok(Format::Candump),
        Some(other) => Err(PyValueError::new_err(format!(
            "unknown capture format {other:?} (pcap, pcapng, candump)"
        ))),
        None => Format::from_extension(path).ok_or_else(|| {
            PyValueError::new_err(format!(
                "cannot tell the capture format of {} (.pcap, .pcapng, .log): give format=",
                path.display()
            ))
        }),
    }
}

pub(crate) fn start(
    shared: &Arc<Shared>,
    path: PathBuf,
    bus: Option<&str>,
    format: Option<&str>,
) -> PyResult<Capture> {
    let format = format_of(&path, format)?;
    let mut core = shared.lock();
    let ids = match bus {
        Some(name) => vec![core.bus_id(name)?],
        None => core.buses.iter().map(|(_, id)| *id).collect(),
    };
    if format == Format::Pcap && ids.len() > 1 {
        return Err(PyValueError::new_err(
            "classic pcap has no channel field: record one bus (bus=) or use pcapng or candump",
        ));
    }
    let file = std::fs::File::create(&path)
        .map_err(|e| err(format!("creating capture {}: {e}", path.display())))?;
    let writer = cantwin_capture::writer(format, std::io::BufWriter::new(file))
        .map_err(|e| err(format!("creating capture {}: {e}", path.display())))?;
    let writer: SharedWriter = Arc::new(Mutex::new(Some(writer)));
    let failed = Arc::new(Mutex::new(None));
    core.with_sim(|sim| {
        for id in ids {
            if let Some(b) = sim.bus_mut(id) {
                b.add_tap(CaptureTap {
                    writer: Arc::clone(&writer),
                    failed: Arc::clone(&failed),
                });
            }
        }
    })?;
    Ok(Capture {
        writer,
        failed,
        path,
    })
}

#[pymethods]
impl Capture {
    /// The file being written.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Write out what is buffered, keep recording.
    fn flush(&self) -> PyResult<()> {
        let mut w = self.writer.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(w) = w.as_mut() {
            w.flush().map_err(|e| err(e.to_string()))?;
        }
        self.check()
    }

    /// Stop recording and complete the file; an error met while recording is raised here.
    fn close(&self) -> PyResult<()> {
        let taken = self
            .writer
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take();
        if let Some(mut w) = taken {
            w.flush().map_err(|e| err(e.to_string()))?;
        }
        self.check()
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    fn __exit__(
        &self,
        _ty: Option<&Bound<'_, PyAny>>,
        _value: Option<&Bound<'_, PyAny>>,
        _tb: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<bool> {
        self.close()?;
        Ok(false)
    }
}

impl Capture {
    fn check(&self) -> PyResult<()> {
        match self
            .failed
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .as_ref()
        {
            Some(e) => Err(err(format!("writing {}: {e}", self.path.display()))),
            None => Ok(()),
        }
    }
}
