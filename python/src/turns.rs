//! Whose turn it is: bus time waits for Python threads that act.
//!
//! # The model
//!
//! In virtual time the bus stands still while Python works and runs while Python waits.
//! A Python thread *acts* when it sends a frame or changes the simulation (writes an object,
//! sets a signal, injects a fault, powers a device, …); it *waits* when it blocks in a
//! receive of a port, in one of `threading`'s waits (`Condition.wait`, and through it
//! `Event.wait`, `queue.Queue.get`, `Semaphore.acquire`; `Thread.join`), or in a call into C
//! that does not come back (`time.sleep`, I/O: the thread stays at the same instruction).
//!
//! A receiver that would run the simulation (virtual time) or hand over a frame (paced) first
//! lets every thread that acted reach its wait, at most the simulation's reaction time (wall
//! clock) after it came back from its act, as far as looks at it can tell (a thread preempted
//! while it holds the GIL cannot be looked at, and loses no time). So the answer to a frame is not simulated, nor delivered, before
//! the thread that sent the frame listens for it: python-canopen's `sync.transmit()` followed
//! by `tpdo[1].wait_for_reception()`, `nmt.state = …` followed by `wait_for_heartbeat()` and
//! a trigger followed by `emcy.wait()` find the answer they wait for, as on a real bus where
//! the device takes longer to answer than the host takes to start waiting.
//!
//! A frame handed to Python can wake a thread that waits: python-canopen's SDO client in
//! `sdo.download()` is woken by the answer, returns, and only then calls `emcy.wait()` for
//! the EMCY that the device sends right after that answer. Such a thread counts as acting
//! from the moment it is found woken (notified in its `Condition.wait`, and not yet back
//! from it) until it waits again, so the EMCY is not handed over before `emcy.wait()`
//! listens, as on a real bus where a host's SDO answer reaches the script before the next
//! frame does.
//!
//! Bus time is unaffected: a frame sent at bus time *t* is queued at *t* and the answer comes
//! when the device gives it; only the moment (wall clock) at which the simulation computes it
//! moves.

use std::time::{Duration, Instant};

use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyDict;

use std::sync::MutexGuard;

use crate::core::{Core, Shared};

/// How long a thread may stay at the same instruction before it counts as blocked in a call
/// into C (`time.sleep`, a socket read). A thread that runs Python code moves on between two
/// looks, which are at least [`POLL`] apart and each take the GIL from it.
const STILL: Duration = Duration::from_millis(5);

/// How long a thread may stay inside the call it acted in before it is no longer waited for
/// (a safety bound: the call returns right after queuing its frame).
const STUCK: Duration = Duration::from_secs(1);

/// How many looks in a row must find a thread at the same instruction, over at least
/// [`STILL`], before it counts as blocked in a call into C.
const STILL_LOOKS: u32 = 3;

/// Longest pause between two looks at threads that have not reached their wait yet.
const POLL: Duration = Duration::from_micros(50);

/// How many looks in a row may follow one another without the pause of [`POLL`], while a
/// thread is found running Python somewhere new at each: the next look waits for the GIL,
/// which such a thread gives up at its wait. Bounded, because a thread that keeps releasing
/// the GIL in short calls into C would otherwise be looked at without end.
const EAGER_LOOKS: u32 = 4;

/// The `threading` functions a thread blocks in. Every python-canopen wait
/// (`wait_for_reception`, `wait_for_heartbeat`, `emcy.wait`, the SDO client's response
/// queue) is a `Condition.wait`.
const THREADING_WAITS: [&str; 3] = ["wait", "join", "_wait_for_tstate_lock"];

impl Shared {
    /// Lock the core on behalf of the calling Python thread, which is about to act on the
    /// simulation: bus time waits for it (this module).
    ///
    /// An act answers the frames handed to Python as a sent frame does (the reaction rule of
    /// `crate::port`); receivers waiting for an answer are woken, and see the change once
    /// the caller releases the lock.
    pub fn lock_acting(&self, py: Python<'_>) -> PyResult<MutexGuard<'_, Core>> {
        let thread = thread_ident(py)?;
        let mut core = self.lock();
        core.acted(thread, true);
        self.delivery
            .pending
            .store(false, std::sync::atomic::Ordering::Release);
        self.changed.notify_all();
        Ok(core)
    }
}

/// Note every thread that acted once and has been woken from its wait (a frame the calling
/// receiver handed to Python notified it): bus time waits for it until it waits again
/// (module documentation). Woken is a thread found notified in its `Condition.wait`, or
/// found running where the look before found it blocked in one (it may have got the GIL
/// before this look). `caller`, the receiver, is not looked at.
///
/// Called by a receiver back for the next frame (the callbacks of the one before have run)
/// before it runs the simulation on within the reaction gap (`crate::port`) or, paced, hands
/// over a frame: where another frame can reach Python before the woken thread waits. A
/// thread that has ended is forgotten.
pub(crate) fn note_woken(py: Python<'_>, shared: &Shared, caller: u64) -> PyResult<()> {
    let actors: Vec<u64> = {
        let core = shared.lock();
        core.actors
            .iter()
            .copied()
            .filter(|&t| t != caller && !core.acting.iter().any(|a| a.thread == t))
            .collect()
    };
    if actors.is_empty() {
        return Ok(());
    }
    let frames = current_frames(py)?;
    let mut seen = Vec::new();
    for thread in actors {
        let wait = match frames.get_item(thread)? {
            None => None,
            Some(frame) => Some(condition_wait(&frame)?),
        };
        seen.push((thread, wait));
    }
    let mut core = shared.lock();
    for (thread, wait) in seen {
        match wait {
            // Ended.
            None => {
                core.actors.retain(|&t| t != thread);
                core.blocked.retain(|&t| t != thread);
            }
            Some(Some(Wait::Blocked)) => core.seen_blocked(thread, true),
            Some(Some(Wait::Notified)) => core.acted(thread, true),
            Some(None) => {
                if core.blocked.contains(&thread) {
                    core.acted(thread, true);
                }
                core.seen_blocked(thread, false);
            }
        }
    }
    Ok(())
}

/// Where a thread stands in `threading.Condition.wait` (through which `Event.wait` and
/// `queue.Queue.get` wait).
#[derive(Debug, PartialEq, Eq)]
enum Wait {
    /// Blocked on its waiter lock, which is still among the condition's waiters.
    Blocked,
    /// Its waiter was taken off the condition's waiters by `notify`: it is about to return.
    Notified,
}

/// Whether `frame` is `Condition.wait` holding a waiter lock, and where it stands; `None`
/// for any other frame (or one that cannot be read).
fn condition_wait(frame: &Bound<'_, PyAny>) -> PyResult<Option<Wait>> {
    if code_kind(frame)? != CodeKind::Wait {
        return Ok(None);
    }
    waiter_state(frame)
}

/// What the code of a frame is to the looks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CodeKind {
    /// A `wait` of `threading` (`Condition.wait`, `Event.wait`, …).
    Wait,
    /// Another of [`THREADING_WAITS`] (`Thread.join` and what it blocks in).
    Join,
    /// Anything else.
    Other,
}

/// How many code objects [`code_kind`] remembers: a thread that is looked at waits in a
/// handful of functions; further ones are told by name each time.
const KNOWN_CODES: usize = 64;

/// The code objects told apart so far, found again by identity: a look takes the GIL from
/// the thread it looks at, and reading two strings out of a code object at every look cost
/// more than the rest of it. Holding them keeps them alive, so no other object can take
/// their place.
static CODES: std::sync::Mutex<Vec<(Py<PyAny>, CodeKind)>> = std::sync::Mutex::new(Vec::new());

/// What the code of `frame` is (its function's name and file, remembered by identity).
fn code_kind(frame: &Bound<'_, PyAny>) -> PyResult<CodeKind> {
    let code = frame.getattr("f_code")?;
    let mut known = CODES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((_, kind)) = known.iter().find(|(c, _)| c.bind(frame.py()).is(&code)) {
        return Ok(*kind);
    }
    let name: String = code.getattr("co_name")?.extract()?;
    let kind = if !in_threading(&code)? || !THREADING_WAITS.contains(&name.as_str()) {
        CodeKind::Other
    } else if name == "wait" {
        CodeKind::Wait
    } else {
        CodeKind::Join
    };
    if known.len() < KNOWN_CODES {
        known.push((code.unbind(), kind));
    }
    Ok(kind)
}

/// Where a frame of `threading`'s `wait` stands by its waiter lock; `None` where it holds
/// none (`Event.wait` itself, a `Condition.wait` not yet blocking).
fn waiter_state(frame: &Bound<'_, PyAny>) -> PyResult<Option<Wait>> {
    let locals = frame.getattr("f_locals")?;
    let (Ok(waiter), Ok(condition)) = (locals.get_item("waiter"), locals.get_item("self")) else {
        return Ok(None);
    };
    let Ok(waiters) = condition.getattr("_waiters") else {
        return Ok(None);
    };
    Ok(Some(if waiters.contains(waiter)? {
        Wait::Blocked
    } else {
        Wait::Notified
    }))
}

/// Whether `code` is a function of the standard library's `threading` module.
fn in_threading(code: &Bound<'_, PyAny>) -> PyResult<bool> {
    let file: String = code.getattr("co_filename")?.extract()?;
    Ok(std::path::Path::new(&file)
        .file_name()
        .is_some_and(|f| f == "threading.py"))
}

/// `threading.get_ident()` of the calling thread (`_thread.get_ident`, looked up once: every
/// send and receive asks).
pub(crate) fn thread_ident(py: Python<'_>) -> PyResult<u64> {
    static GET_IDENT: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    GET_IDENT
        .import(py, "_thread", "get_ident")?
        .call0()?
        .extract()
}

/// `sys._current_frames`, looked up once.
fn current_frames<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    static CURRENT_FRAMES: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    Ok(CURRENT_FRAMES
        .import(py, "sys", "_current_frames")?
        .call0()?
        .cast_into::<PyDict>()?)
}

/// Where a thread was seen last: its top frame and instruction, since when, and how many
/// looks in a row found it there.
struct Spot {
    thread: u64,
    frame: Py<PyAny>,
    lasti: i64,
    since: Instant,
    looks: u32,
}

/// Wait until every thread that acted waits, or was seen running for longer than the
/// reaction time since it came back from its act (`true`), or until `deadline` (`false`).
/// Call it without holding the core's lock and without the GIL.
///
/// A thread's time is judged only at a look: while it holds the GIL (a host that preempts it
/// there, say) no look can happen, and it loses nothing. A thread still inside the call it
/// acted in is waited for, past `deadline` if need be: it comes back as soon as its frame is
/// queued.
pub(crate) fn settle(shared: &Shared, deadline: Instant) -> bool {
    let mut spots: Vec<Spot> = Vec::new();
    let mut eager = 0;
    loop {
        let acting = shared.lock().acting_threads();
        if acting.is_empty() {
            return true;
        }
        // Only a thread back in Python can have reached a wait.
        let threads: Vec<u64> = acting.iter().filter(|a| a.1).map(|a| a.0).collect();
        // If Python cannot be asked (an interpreter shutting down), nobody is waited for:
        // a receiver must never hang on it.
        let Look {
            waiting,
            blocked,
            moved,
        } = if threads.is_empty() {
            Look::default()
        } else {
            Python::attach(|py| waiting_threads(py, &threads, &mut spots)).unwrap_or_else(|_| {
                Look {
                    waiting: threads.clone(),
                    ..Look::default()
                }
            })
        };
        let mut core = shared.lock();
        for &thread in &threads {
            core.seen_blocked(thread, blocked.contains(&thread));
        }
        let limit = core.reaction_time;
        core.acting.retain(|a| {
            if a.returned {
                // Looked at just now: it waits, or has run too long to be waited for.
                let ran_too_long = threads.contains(&a.thread) && a.since.elapsed() >= limit;
                !(waiting.contains(&a.thread) || ran_too_long)
            } else {
                a.since.elapsed() < STUCK
            }
        });
        let left = core.acting.iter().any(|a| a.returned);
        if core.acting.is_empty() {
            return true;
        }
        if left && Instant::now() >= deadline {
            return false;
        }
        if moved && eager < EAGER_LOOKS {
            // On its way to its wait, holding the GIL: the next look gets the GIL when the
            // thread lets go of it there (or at the interpreter's switch interval), at once
            // rather than up to a pause later.
            eager += 1;
            continue;
        }
        eager = 0;
        // Until the next look: a thread that acts again (its next request) wakes this at
        // once, one still at the same place is looked at again after the pause.
        drop(
            shared
                .changed
                .wait_timeout(core, POLL)
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        );
    }
}

/// What a look at the threads that acted found.
#[derive(Debug, Default)]
struct Look {
    /// Those that wait (module documentation; a thread that ended waits).
    waiting: Vec<u64>,
    /// Those of them blocked in a `Condition.wait`.
    blocked: Vec<u64>,
    /// Whether one that does not wait was found somewhere other than at the look before:
    /// running Python.
    moved: bool,
}

/// Looks at `threads` (module documentation).
fn waiting_threads(py: Python<'_>, threads: &[u64], spots: &mut Vec<Spot>) -> PyResult<Look> {
    let frames = current_frames(py)?;
    let mut waiting = Vec::new();
    let mut blocked = Vec::new();
    let mut moved = false;
    for &thread in threads {
        let Some(frame) = frames.get_item(thread)? else {
            waiting.push(thread);
            continue;
        };
        let kind = code_kind(&frame)?;
        if kind != CodeKind::Other {
            // A woken thread is on its way out of the wait, not in it.
            let wait = if kind == CodeKind::Wait {
                waiter_state(&frame)?
            } else {
                None
            };
            match wait {
                // Woken, not yet running: neither waiting nor on its way anywhere, so not
                // looked at again before the pause (the next look would only take the GIL
                // it needs to run).
                Some(Wait::Notified) => continue,
                wait => {
                    if wait == Some(Wait::Blocked) {
                        blocked.push(thread);
                    }
                    waiting.push(thread);
                    continue;
                }
            }
        }
        let lasti: i64 = frame.getattr("f_lasti")?.extract()?;
        match spots.iter_mut().find(|s| s.thread == thread) {
            Some(s) if s.frame.bind(py).is(&frame) && s.lasti == lasti => {
                s.looks += 1;
                if s.looks >= STILL_LOOKS && s.since.elapsed() >= STILL {
                    waiting.push(thread);
                }
            }
            Some(s) => {
                s.frame = frame.unbind();
                s.lasti = lasti;
                s.since = Instant::now();
                s.looks = 1;
                moved = true;
            }
            None => {
                spots.push(Spot {
                    thread,
                    frame: frame.unbind(),
                    lasti,
                    since: Instant::now(),
                    looks: 1,
                });
                moved = true;
            }
        }
    }
    Ok(Look {
        waiting,
        blocked,
        moved,
    })
}
