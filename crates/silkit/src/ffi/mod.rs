//! The only place that calls into `libSilKit.so`: loading the library, the C handles behind
//! safe types, and the callbacks SIL Kit makes back into Rust.
//!
//! Safety rests on three rules, each enforced here and nowhere else:
//!
//! * **Handles never outlive their participant.** Every handle ([`CanController`],
//!   [`Lifecycle`], [`TimeSync`]) holds the participant's shared state; a call through a handle
//!   holds a read lock on its `alive` flag, and [`Participant`]'s drop clears the flag under
//!   the write lock *before* `SilKit_Participant_Destroy` frees the C objects. A handle used
//!   afterwards gets [`Error::Destroyed`].
//! * **Callback contexts outlive every callback.** A handler closure is boxed and kept by
//!   the participant; SIL Kit gets a pointer to it. The boxes are freed only after
//!   `SilKit_Participant_Destroy` has returned, which joins SIL Kit's threads.
//! * **Data handed to a callback is copied before the callback returns** (it lives on SIL
//!   Kit's stack, `src/capi/CapiCan.cpp`), and a panic in a handler is caught at the boundary
//!   (unwinding into C is undefined).
//!
//! Handlers are `Fn + Send + Sync`: SIL Kit may call a handler again from inside a call the
//! handler makes (a trivial-mode `SendFrame` acknowledges synchronously), so a handler must
//! not hold a lock it would need again; it synchronises what it shares itself.

mod raw;

use core::ffi::{CStr, c_char, c_void};
use std::ffi::CString;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError, RwLock};

use crate::error::Error;
use crate::types::{
    CanFrame, ControllerState, Direction, DirectionMask, ErrorState, ErrorStateChangeEvent,
    FrameEvent, OperationMode, ParticipantState, StateChangeEvent, TransmitEvent, TransmitStatus,
};

/// The library file name SIL Kit installs on Linux.
pub const LIBRARY_NAME: &str = "libSilKit.so";

/// A loaded `libSilKit.so`. Cheap to clone.
#[derive(Clone)]
pub struct SilKit {
    api: Arc<Api>,
}

struct Api {
    f: raw::Functions,
    path: PathBuf,
    /// Kept open as long as any function pointer above may be called.
    _lib: libloading::Library,
}

impl core::fmt::Debug for SilKit {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SilKit")
            .field("library", &self.api.path)
            .finish_non_exhaustive()
    }
}

impl SilKit {
    /// Load SIL Kit from, in this order: the file `CANTWIN_SILKIT_LIB` names, `libSilKit.so`
    /// in the directory `CANTWIN_SILKIT_DIR` names, or `libSilKit.so` by the system's library
    /// search (`LD_LIBRARY_PATH`, the loader cache). The error says what was tried and how to
    /// get SIL Kit.
    pub fn load() -> Result<SilKit, Error> {
        let mut candidates = Vec::new();
        if let Some(p) = std::env::var_os("CANTWIN_SILKIT_LIB") {
            candidates.push(PathBuf::from(p));
        }
        if let Some(d) = std::env::var_os("CANTWIN_SILKIT_DIR") {
            candidates.push(PathBuf::from(d).join(LIBRARY_NAME));
        }
        candidates.push(PathBuf::from(LIBRARY_NAME));
        let mut tried = Vec::new();
        for c in candidates {
            match SilKit::load_from(&c) {
                Err(Error::NotFound { tried: why }) => tried.push(why),
                other => return other,
            }
        }
        Err(Error::NotFound {
            tried: tried.join("; "),
        })
    }

    /// Load SIL Kit from `path` (a bare file name is looked up by the system's library
    /// search).
    pub fn load_from(path: &Path) -> Result<SilKit, Error> {
        // SAFETY: opening a shared library runs its initialisers; libSilKit's are those of a
        // C++ library (static objects), which have no preconditions on the caller.
        let lib = unsafe { libloading::Library::new(path) }.map_err(|e| Error::NotFound {
            tried: format!("{}: {e}", path.display()),
        })?;
        let f = load_functions(&lib, path)?;
        let api = Api {
            f,
            path: path.to_path_buf(),
            _lib: lib,
        };
        let kit = SilKit { api: Arc::new(api) };
        let mut major = 0u32;
        // SAFETY: a valid out-pointer, as `capi/Version.h` asks.
        let rc = unsafe { (kit.api.f.version_major)(&mut major) };
        kit.api.check("SilKit_Version_Major", rc)?;
        if major != 5 {
            return Err(Error::WrongVersion {
                library: path.to_path_buf(),
                version: kit.version().unwrap_or_else(|_| major.to_string()),
            });
        }
        Ok(kit)
    }

    /// The library's version string (`SilKit_Version_String`), e.g. `5.0.3`.
    pub fn version(&self) -> Result<String, Error> {
        let mut s: *const c_char = core::ptr::null();
        // SAFETY: a valid out-pointer; the string is static in the library.
        let rc = unsafe { (self.api.f.version_string)(&mut s) };
        self.api.check("SilKit_Version_String", rc)?;
        Ok(self.api.string(s))
    }

    /// The file the library was loaded from.
    pub fn path(&self) -> &Path {
        &self.api.path
    }

    /// Whether the library offers the experimental network simulator API
    /// (`SilKit_Experimental_NetworkSimulator_*`, `SilKit_Experimental_CanEventProducer_Produce`).
    pub fn has_network_simulator(&self) -> bool {
        let f = &self.api.f;
        f.network_simulator_create.is_some()
            && f.network_simulator_simulate_network.is_some()
            && f.network_simulator_start.is_some()
            && f.can_event_producer_produce.is_some()
    }
}

fn load_functions(lib: &libloading::Library, path: &Path) -> Result<raw::Functions, Error> {
    /// Look a required function up; the type comes from the field it is assigned to.
    macro_rules! req {
        ($name:literal) => {{
            // SAFETY: the symbol is declared in `raw` with the signature of SIL Kit's header;
            // the pointer is only called while `lib` is open (`Api` keeps it).
            let sym = unsafe { lib.get(concat!($name, "\0").as_bytes()) }.map_err(|_| {
                Error::MissingSymbol {
                    library: path.to_path_buf(),
                    symbol: $name,
                }
            })?;
            *sym
        }};
    }
    /// Look an experimental function up; its absence is reported when it is used.
    macro_rules! opt {
        ($name:literal) => {{
            // SAFETY: as above.
            unsafe { lib.get(concat!($name, "\0").as_bytes()) }
                .ok()
                .map(|sym| *sym)
        }};
    }
    Ok(raw::Functions {
        version_string: req!("SilKit_Version_String"),
        version_major: req!("SilKit_Version_Major"),
        get_last_error_string: req!("SilKit_GetLastErrorString"),
        return_code_to_string: req!("SilKit_ReturnCodeToString"),
        configuration_from_string: req!("SilKit_ParticipantConfiguration_FromString"),
        configuration_destroy: req!("SilKit_ParticipantConfiguration_Destroy"),
        participant_create: req!("SilKit_Participant_Create"),
        participant_destroy: req!("SilKit_Participant_Destroy"),
        can_create: req!("SilKit_CanController_Create"),
        can_start: req!("SilKit_CanController_Start"),
        can_stop: req!("SilKit_CanController_Stop"),
        can_reset: req!("SilKit_CanController_Reset"),
        can_send_frame: req!("SilKit_CanController_SendFrame"),
        can_set_baud_rate: req!("SilKit_CanController_SetBaudRate"),
        can_add_frame_handler: req!("SilKit_CanController_AddFrameHandler"),
        can_add_frame_transmit_handler: req!("SilKit_CanController_AddFrameTransmitHandler"),
        can_add_state_change_handler: req!("SilKit_CanController_AddStateChangeHandler"),
        can_add_error_state_change_handler: req!("SilKit_CanController_AddErrorStateChangeHandler"),
        lifecycle_create: req!("SilKit_LifecycleService_Create"),
        lifecycle_set_communication_ready_handler: req!(
            "SilKit_LifecycleService_SetCommunicationReadyHandler"
        ),
        lifecycle_set_stop_handler: req!("SilKit_LifecycleService_SetStopHandler"),
        lifecycle_set_shutdown_handler: req!("SilKit_LifecycleService_SetShutdownHandler"),
        lifecycle_set_abort_handler: req!("SilKit_LifecycleService_SetAbortHandler"),
        lifecycle_start: req!("SilKit_LifecycleService_StartLifecycle"),
        lifecycle_wait: req!("SilKit_LifecycleService_WaitForLifecycleToComplete"),
        lifecycle_stop: req!("SilKit_LifecycleService_Stop"),
        lifecycle_state: req!("SilKit_LifecycleService_State"),
        time_sync_create: req!("SilKit_TimeSyncService_Create"),
        time_sync_set_step_handler: req!("SilKit_TimeSyncService_SetSimulationStepHandler"),
        time_sync_now: req!("SilKit_TimeSyncService_Now"),
        system_monitor_create: req!("SilKit_SystemMonitor_Create"),
        system_monitor_add_participant_status_handler: req!(
            "SilKit_SystemMonitor_AddParticipantStatusHandler"
        ),
        system_monitor_set_participant_disconnected_handler: req!(
            "SilKit_SystemMonitor_SetParticipantDisconnectedHandler"
        ),
        system_controller_create: opt!("SilKit_Experimental_SystemController_Create"),
        system_controller_set_workflow: opt!(
            "SilKit_Experimental_SystemController_SetWorkflowConfiguration"
        ),
        network_simulator_create: opt!("SilKit_Experimental_NetworkSimulator_Create"),
        network_simulator_simulate_network: opt!(
            "SilKit_Experimental_NetworkSimulator_SimulateNetwork"
        ),
        network_simulator_start: opt!("SilKit_Experimental_NetworkSimulator_Start"),
        can_event_producer_produce: opt!("SilKit_Experimental_CanEventProducer_Produce"),
    })
}

impl Api {
    /// A C string owned by the library, copied.
    fn string(&self, s: *const c_char) -> String {
        if s.is_null() {
            return String::new();
        }
        // SAFETY: SIL Kit returns NUL-terminated strings that stay valid until the next call
        // on this thread; it is copied at once.
        unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
    }

    /// `Ok` for SUCCESS, else the error with SIL Kit's text for it. The last-error string is
    /// thread-local in SIL Kit, so this runs on the thread that made the call.
    fn check(&self, function: &'static str, rc: raw::ReturnCode) -> Result<(), Error> {
        if rc == raw::SUCCESS {
            return Ok(());
        }
        // SAFETY: no arguments; returns a thread-local string.
        let mut message = self.string(unsafe { (self.f.get_last_error_string)() });
        if message.is_empty() {
            let mut s: *const c_char = core::ptr::null();
            // SAFETY: a valid out-pointer; the text is static.
            if unsafe { (self.f.return_code_to_string)(&mut s, rc) } == raw::SUCCESS {
                message = self.string(s);
            }
        }
        Err(Error::Call {
            function,
            code: rc,
            message,
        })
    }
}

fn cstring(what: &'static str, value: &str) -> Result<CString, Error> {
    CString::new(value).map_err(|_| Error::Nul {
        what,
        value: value.to_string(),
    })
}

/// What every handle of one participant shares.
struct Inner {
    api: Arc<Api>,
    raw: *mut raw::Participant,
    /// Cleared (under the write lock) before the participant is destroyed.
    alive: RwLock<bool>,
    /// Handler closures SIL Kit holds pointers to; freed after the participant is destroyed.
    contexts: Mutex<Vec<Box<dyn Send + Sync>>>,
}

// SAFETY: SIL Kit's participant and its services are thread-safe C++ objects (their calls
// may be made from any thread, `docs/api/api.rst`); `raw` is only dereferenced by SIL Kit,
// and never after `alive` was cleared.
unsafe impl Send for Inner {}
// SAFETY: as above.
unsafe impl Sync for Inner {}

impl Inner {
    /// Run `f` while the participant is guaranteed alive.
    fn call<R>(&self, f: impl FnOnce(&Api) -> R) -> Result<R, Error> {
        let alive = self.alive.read().unwrap_or_else(PoisonError::into_inner);
        if !*alive {
            return Err(Error::Destroyed);
        }
        Ok(f(&self.api))
    }

    /// Keep a handler closure alive for the participant's lifetime; returns the pointer SIL
    /// Kit gets as its context.
    fn keep<F: Send + Sync + 'static>(&self, f: F) -> *mut c_void {
        let boxed = Box::new(f);
        let ptr = &*boxed as *const F as *mut c_void;
        self.contexts
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(boxed);
        ptr
    }
}

/// A SIL Kit simulation participant (`SilKit_Participant`): joined to a registry, owner of
/// every controller and service created from it. Dropping it leaves the simulation.
pub struct Participant {
    inner: Arc<Inner>,
    name: String,
}

impl core::fmt::Debug for Participant {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Participant")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl Participant {
    /// Join the simulation at `registry_uri` (e.g. `silkit://127.0.0.1:8500`) as `name`, with a
    /// participant configuration in SIL Kit's YAML or JSON form (`""` for the defaults). Blocks
    /// while it connects; fails if no registry answers.
    pub fn create(
        kit: &SilKit,
        name: &str,
        registry_uri: &str,
        configuration: &str,
    ) -> Result<Participant, Error> {
        let api = &kit.api;
        let c_name = cstring("participant name", name)?;
        let c_uri = cstring("registry URI", registry_uri)?;
        let c_cfg = cstring("participant configuration", configuration)?;
        let mut cfg: *mut raw::ParticipantConfiguration = core::ptr::null_mut();
        // SAFETY: valid out-pointer and NUL-terminated string.
        let rc = unsafe { (api.f.configuration_from_string)(&mut cfg, c_cfg.as_ptr()) };
        api.check("SilKit_ParticipantConfiguration_FromString", rc)?;
        let mut p: *mut raw::Participant = core::ptr::null_mut();
        // SAFETY: every argument is valid and non-NULL; the configuration is copied by the
        // call (`src/capi/CapiParticipant.cpp`), so it is destroyed right after.
        let rc =
            unsafe { (api.f.participant_create)(&mut p, cfg, c_name.as_ptr(), c_uri.as_ptr()) };
        let created = api.check("SilKit_Participant_Create", rc);
        // SAFETY: `cfg` came from FromString and is destroyed once.
        unsafe { (api.f.configuration_destroy)(cfg) };
        created?;
        Ok(Participant {
            inner: Arc::new(Inner {
                api: Arc::clone(api),
                raw: p,
                alive: RwLock::new(true),
                contexts: Mutex::new(Vec::new()),
            }),
            name: name.to_string(),
        })
    }

    /// The participant's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Create a CAN controller `name` on the CAN network `network` (controllers on networks
    /// of the same name share a bus).
    pub fn can_controller(&self, name: &str, network: &str) -> Result<CanController, Error> {
        let c_name = cstring("controller name", name)?;
        let c_net = cstring("network name", network)?;
        let mut c: *mut raw::CanController = core::ptr::null_mut();
        let p = self.inner.raw;
        self.inner.call(|api| {
            // SAFETY: the participant is alive; strings are NUL-terminated.
            let rc = unsafe { (api.f.can_create)(&mut c, p, c_name.as_ptr(), c_net.as_ptr()) };
            api.check("SilKit_CanController_Create", rc)
        })??;
        Ok(CanController {
            inner: Arc::clone(&self.inner),
            raw: c,
        })
    }

    /// Create the participant's lifecycle service (one per participant).
    pub fn lifecycle(&self, mode: OperationMode) -> Result<Lifecycle, Error> {
        let cfg = raw::LifecycleConfiguration {
            header: raw::StructHeader::new(raw::LIFECYCLE_CONFIGURATION_ID),
            operation_mode: match mode {
                OperationMode::Coordinated => 10,
                OperationMode::Autonomous => 20,
            },
        };
        let mut ls: *mut raw::LifecycleService = core::ptr::null_mut();
        let p = self.inner.raw;
        self.inner.call(|api| {
            // SAFETY: the participant is alive; `cfg` has its header set as
            // `SilKit_Struct_Init` would (vectorgrp/sil-kit#351).
            let rc = unsafe { (api.f.lifecycle_create)(&mut ls, p, &cfg) };
            api.check("SilKit_LifecycleService_Create", rc)
        })??;
        Ok(Lifecycle {
            inner: Arc::clone(&self.inner),
            raw: ls,
        })
    }

    /// Create the participant's system monitor (one per participant), which reports the
    /// other participants' states and departures.
    pub fn system_monitor(&self) -> Result<SystemMonitor, Error> {
        let mut m: *mut raw::SystemMonitor = core::ptr::null_mut();
        let p = self.inner.raw;
        self.inner.call(|api| {
            // SAFETY: the participant is alive; the monitor is owned by it.
            let rc = unsafe { (api.f.system_monitor_create)(&mut m, p) };
            api.check("SilKit_SystemMonitor_Create", rc)
        })??;
        Ok(SystemMonitor {
            inner: Arc::clone(&self.inner),
            raw: m,
        })
    }

    /// Become the system controller (experimental API) and set the participants whose
    /// lifecycle the coordinated simulation waits for. Set once per simulation.
    pub fn set_required_participants(&self, names: &[&str]) -> Result<(), Error> {
        let create = self
            .inner
            .api
            .f
            .system_controller_create
            .ok_or(Error::NoExperimental(
                "SilKit_Experimental_SystemController_Create",
            ))?;
        let set = self
            .inner
            .api
            .f
            .system_controller_set_workflow
            .ok_or(Error::NoExperimental(
                "SilKit_Experimental_SystemController_SetWorkflowConfiguration",
            ))?;
        let owned: Vec<CString> = names
            .iter()
            .map(|n| cstring("participant name", n))
            .collect::<Result<_, _>>()?;
        let mut ptrs: Vec<*mut c_char> = owned.iter().map(|s| s.as_ptr() as *mut c_char).collect();
        let mut list = raw::StringList {
            num_strings: ptrs.len(),
            strings: ptrs.as_mut_ptr(),
        };
        let wf = raw::WorkflowConfiguration {
            header: raw::StructHeader::new(raw::WORKFLOW_CONFIGURATION_ID),
            required_participant_names: &mut list,
        };
        let p = self.inner.raw;
        self.inner.call(|api| {
            let mut sc: *mut raw::SystemController = core::ptr::null_mut();
            // SAFETY: the participant is alive; the controller it returns is owned by it.
            let rc = unsafe { create(&mut sc, p) };
            api.check("SilKit_Experimental_SystemController_Create", rc)?;
            // SAFETY: `wf` and the strings it points to live across the call, which copies
            // them.
            let rc = unsafe { set(sc, &wf) };
            api.check(
                "SilKit_Experimental_SystemController_SetWorkflowConfiguration",
                rc,
            )
        })?
    }

    /// Block until the lifecycle has ended (`SilKit_LifecycleService_WaitForLifecycleToComplete`,
    /// callable once); returns the final state. Not from a SIL Kit handler.
    pub fn wait_for_lifecycle(&self, lifecycle: &Lifecycle) -> Result<ParticipantState, Error> {
        if !Arc::ptr_eq(&self.inner, &lifecycle.inner) {
            return Err(Error::Call {
                function: "SilKit_LifecycleService_WaitForLifecycleToComplete",
                code: 4,
                message: "the lifecycle belongs to another participant".into(),
            });
        }
        let mut state: raw::ParticipantState = 0;
        // The participant cannot be destroyed while `self` is borrowed, so no lock is held
        // across this long wait (handles keep working meanwhile).
        // SAFETY: a valid lifecycle of this live participant and a non-NULL out-pointer.
        let rc = unsafe { (self.inner.api.f.lifecycle_wait)(lifecycle.raw, &mut state) };
        self.inner
            .api
            .check("SilKit_LifecycleService_WaitForLifecycleToComplete", rc)?;
        Ok(ParticipantState::from_raw(state))
    }

    /// [`Participant::wait_for_lifecycle`] for at most `timeout`: the C API's wait has no
    /// bound (a coordinated participant waits for ever for a required peer that never
    /// joins), so this polls the state until `Shutdown`, the state in which SIL Kit
    /// completes that wait, and only then takes the final state.
    /// After `timeout` it gives [`Error::Timeout`] with the state the lifecycle is stuck in;
    /// the participant stays usable (e.g. to be destroyed).
    pub fn wait_for_lifecycle_timeout(
        &self,
        lifecycle: &Lifecycle,
        timeout: std::time::Duration,
    ) -> Result<ParticipantState, Error> {
        let until = std::time::Instant::now() + timeout;
        loop {
            let state = lifecycle.state()?;
            if state == ParticipantState::Shutdown {
                return self.wait_for_lifecycle(lifecycle);
            }
            let left = until.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Err(Error::Timeout {
                    waited_for: "the lifecycle reaching Shutdown",
                    after: timeout,
                    state,
                });
            }
            std::thread::sleep(left.min(std::time::Duration::from_millis(10)));
        }
    }
}

impl Drop for Participant {
    fn drop(&mut self) {
        *self
            .inner
            .alive
            .write()
            .unwrap_or_else(PoisonError::into_inner) = false;
        // SAFETY: no handle can call into the participant any more (`alive` is cleared and
        // no call is in progress: the write lock was taken); destroyed once.
        unsafe { (self.inner.api.f.participant_destroy)(self.inner.raw) };
        // SIL Kit's threads are joined: no callback can run, the contexts can go.
        let contexts = std::mem::take(
            &mut *self
                .inner
                .contexts
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        );
        drop(contexts);
    }
}

/// Catch a panic at the C boundary: unwinding into SIL Kit is undefined behaviour. The
/// handler's work is lost; SIL Kit goes on.
fn guarded(f: impl FnOnce()) {
    let _ = catch_unwind(AssertUnwindSafe(f));
}

/// A CAN controller of a participant (`SilKit_CanController`). Cheap to clone and `Send`, for
/// use from handlers and other threads.
#[derive(Clone)]
pub struct CanController {
    inner: Arc<Inner>,
    raw: *mut raw::CanController,
}

// SAFETY: see `Inner`; the controller is a thread-safe object owned by the participant.
unsafe impl Send for CanController {}
// SAFETY: as above.
unsafe impl Sync for CanController {}

impl core::fmt::Debug for CanController {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("CanController").finish_non_exhaustive()
    }
}

unsafe extern "C" fn frame_trampoline<F: Fn(FrameEvent) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _controller: *mut raw::CanController,
    event: *mut raw::CanFrameEvent,
) {
    if ctx.is_null() || event.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `F` kept by the participant; the event and its frame are valid
    // during the call and copied here.
    let (f, event) = unsafe { (&*(ctx as *const F), &*event) };
    let Some(frame) = (unsafe { copy_frame(event.frame) }) else {
        return;
    };
    let ev = FrameEvent {
        timestamp: event.timestamp,
        frame,
        direction: if event.direction == 1 {
            Direction::Send
        } else {
            Direction::Receive
        },
        user_context: event.user_context as usize,
    };
    guarded(|| f(ev));
}

/// Copy a C frame; `None` for NULL.
///
/// # Safety
/// `frame` is NULL or a valid `SilKit_CanFrame` whose data pointer covers `size` bytes.
unsafe fn copy_frame(frame: *const raw::CanFrame) -> Option<CanFrame> {
    if frame.is_null() {
        return None;
    }
    // SAFETY: the caller's contract.
    let frame = unsafe { &*frame };
    let data = if frame.data.data.is_null() || frame.data.size == 0 {
        Vec::new()
    } else {
        // SAFETY: the caller's contract; the payload is at most 2048 bytes (CAN XL).
        unsafe { std::slice::from_raw_parts(frame.data.data, frame.data.size.min(2048)) }.to_vec()
    };
    Some(CanFrame {
        id: frame.id,
        flags: frame.flags,
        dlc: frame.dlc,
        data,
    })
}

/// A C view of a frame; `frame` must outlive the view.
fn c_frame(frame: &CanFrame) -> raw::CanFrame {
    raw::CanFrame {
        header: raw::StructHeader::new(raw::CAN_FRAME_ID),
        id: frame.id,
        flags: frame.flags,
        dlc: frame.dlc,
        sdt: 0,
        vcid: 0,
        af: 0,
        data: raw::ByteVector {
            data: frame.data.as_ptr(),
            size: frame.data.len(),
        },
    }
}

unsafe extern "C" fn transmit_trampoline<F: Fn(TransmitEvent) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _controller: *mut raw::CanController,
    event: *mut raw::CanFrameTransmitEvent,
) {
    if ctx.is_null() || event.is_null() {
        return;
    }
    // SAFETY: as in `frame_trampoline`.
    let (f, event) = unsafe { (&*(ctx as *const F), &*event) };
    // `canId` exists from version 2 of the structure on (`capi/Can.h`).
    let can_id = if event.header.struct_version() >= 2 {
        event.can_id
    } else {
        0
    };
    let ev = TransmitEvent {
        timestamp: event.timestamp,
        status: TransmitStatus::from_raw(event.status),
        can_id,
        user_context: event.user_context as usize,
    };
    guarded(|| f(ev));
}

unsafe extern "C" fn state_trampoline<F: Fn(StateChangeEvent) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _controller: *mut raw::CanController,
    event: *mut raw::CanStateChangeEvent,
) {
    if ctx.is_null() || event.is_null() {
        return;
    }
    // SAFETY: as in `frame_trampoline`.
    let (f, event) = unsafe { (&*(ctx as *const F), &*event) };
    let ev = StateChangeEvent {
        timestamp: event.timestamp,
        state: ControllerState::from_raw(event.state),
    };
    guarded(|| f(ev));
}

unsafe extern "C" fn error_state_trampoline<
    F: Fn(ErrorStateChangeEvent) + Send + Sync + 'static,
>(
    ctx: *mut c_void,
    _controller: *mut raw::CanController,
    event: *mut raw::CanErrorStateChangeEvent,
) {
    if ctx.is_null() || event.is_null() {
        return;
    }
    // SAFETY: as in `frame_trampoline`.
    let (f, event) = unsafe { (&*(ctx as *const F), &*event) };
    let ev = ErrorStateChangeEvent {
        timestamp: event.timestamp,
        error_state: ErrorState::from_raw(event.error_state),
    };
    guarded(|| f(ev));
}

impl CanController {
    fn simple(
        &self,
        function: &'static str,
        call: impl FnOnce(&raw::Functions, *mut raw::CanController) -> raw::ReturnCode,
    ) -> Result<(), Error> {
        let c = self.raw;
        self.inner.call(|api| {
            let rc = call(&api.f, c);
            api.check(function, rc)
        })?
    }

    /// Start the controller (it takes part in the bus).
    pub fn start(&self) -> Result<(), Error> {
        // SAFETY: a controller of a live participant.
        self.simple("SilKit_CanController_Start", |f, c| unsafe {
            (f.can_start)(c)
        })
    }

    /// Stop the controller.
    pub fn stop(&self) -> Result<(), Error> {
        // SAFETY: a controller of a live participant.
        self.simple("SilKit_CanController_Stop", |f, c| unsafe {
            (f.can_stop)(c)
        })
    }

    /// Reset the controller: error counters cleared, state Uninit, pending transmissions
    /// cancelled.
    pub fn reset(&self) -> Result<(), Error> {
        // SAFETY: a controller of a live participant.
        self.simple("SilKit_CanController_Reset", |f, c| unsafe {
            (f.can_reset)(c)
        })
    }

    /// Set the bit rates in bit/s (only a network simulator uses them).
    pub fn set_baud_rate(&self, rate: u32, fd_rate: u32, xl_rate: u32) -> Result<(), Error> {
        // SAFETY: a controller of a live participant.
        self.simple("SilKit_CanController_SetBaudRate", |f, c| unsafe {
            (f.can_set_baud_rate)(c, rate, fd_rate, xl_rate)
        })
    }

    /// Request the transmission of `frame`; `tag` comes back in the transmit event (and in
    /// the sender's own frame event).
    pub fn send(&self, frame: &CanFrame, tag: usize) -> Result<(), Error> {
        let mut cf = c_frame(frame);
        // SAFETY: a controller of a live participant; the frame and its payload live across
        // the call, which copies them (`src/capi/CapiCan.cpp`). The tag is an opaque value.
        self.simple("SilKit_CanController_SendFrame", |f, c| unsafe {
            (f.can_send_frame)(c, &mut cf, tag as *mut c_void)
        })
    }

    /// Call `handler` for every frame of the given directions.
    pub fn on_frame(
        &self,
        directions: DirectionMask,
        handler: impl Fn(FrameEvent) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        self.add(handler, |f, c, ctx, h: raw::CanFrameHandler| {
            let mut id = 0;
            // SAFETY: a controller of a live participant; `ctx` lives as long as it does.
            let rc = unsafe { (f.can_add_frame_handler)(c, ctx, h, directions.raw(), &mut id) };
            ("SilKit_CanController_AddFrameHandler", rc)
        })
    }

    fn add<F: Send + Sync + 'static, H: TrampolineOf<F>>(
        &self,
        handler: F,
        register: impl FnOnce(
            &raw::Functions,
            *mut raw::CanController,
            *mut c_void,
            H,
        ) -> (&'static str, raw::ReturnCode),
    ) -> Result<(), Error> {
        let ctx = self.inner.keep(handler);
        let c = self.raw;
        self.inner.call(|api| {
            let (function, rc) = register(&api.f, c, ctx, H::trampoline());
            api.check(function, rc)
        })?
    }

    /// Call `handler` for every transmit acknowledgement (every status).
    pub fn on_transmit(
        &self,
        handler: impl Fn(TransmitEvent) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        self.add(handler, |f, c, ctx, h: raw::CanFrameTransmitHandler| {
            let mut id = 0;
            // SAFETY: as in `on_frame`; 7 is `SilKit_CanTransmitStatus_DefaultMask`.
            let rc = unsafe { (f.can_add_frame_transmit_handler)(c, ctx, h, 7, &mut id) };
            ("SilKit_CanController_AddFrameTransmitHandler", rc)
        })
    }

    /// Call `handler` on every controller state change.
    pub fn on_state_change(
        &self,
        handler: impl Fn(StateChangeEvent) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        self.add(handler, |f, c, ctx, h: raw::CanStateChangeHandler| {
            let mut id = 0;
            // SAFETY: as in `on_frame`.
            let rc = unsafe { (f.can_add_state_change_handler)(c, ctx, h, &mut id) };
            ("SilKit_CanController_AddStateChangeHandler", rc)
        })
    }

    /// Call `handler` on every error state change.
    pub fn on_error_state_change(
        &self,
        handler: impl Fn(ErrorStateChangeEvent) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        self.add(handler, |f, c, ctx, h: raw::CanErrorStateChangeHandler| {
            let mut id = 0;
            // SAFETY: as in `on_frame`.
            let rc = unsafe { (f.can_add_error_state_change_handler)(c, ctx, h, &mut id) };
            ("SilKit_CanController_AddErrorStateChangeHandler", rc)
        })
    }
}

/// The C trampoline that calls a closure of type `F`.
trait TrampolineOf<F> {
    fn trampoline() -> Self;
}

impl<F: Fn(FrameEvent) + Send + Sync + 'static> TrampolineOf<F> for raw::CanFrameHandler {
    fn trampoline() -> Self {
        frame_trampoline::<F>
    }
}
impl<F: Fn(TransmitEvent) + Send + Sync + 'static> TrampolineOf<F>
    for raw::CanFrameTransmitHandler
{
    fn trampoline() -> Self {
        transmit_trampoline::<F>
    }
}
impl<F: Fn(StateChangeEvent) + Send + Sync + 'static> TrampolineOf<F>
    for raw::CanStateChangeHandler
{
    fn trampoline() -> Self {
        state_trampoline::<F>
    }
}
impl<F: Fn(ErrorStateChangeEvent) + Send + Sync + 'static> TrampolineOf<F>
    for raw::CanErrorStateChangeHandler
{
    fn trampoline() -> Self {
        error_state_trampoline::<F>
    }
}

/// The lifecycle service of a participant (`SilKit_LifecycleService`). Cheap to clone.
#[derive(Clone)]
pub struct Lifecycle {
    inner: Arc<Inner>,
    raw: *mut raw::LifecycleService,
}

// SAFETY: see `Inner`.
unsafe impl Send for Lifecycle {}
// SAFETY: as above.
unsafe impl Sync for Lifecycle {}

impl core::fmt::Debug for Lifecycle {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Lifecycle").finish_non_exhaustive()
    }
}

unsafe extern "C" fn lifecycle_trampoline<F: Fn() + Send + Sync + 'static>(
    ctx: *mut c_void,
    _ls: *mut raw::LifecycleService,
) {
    if ctx.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `F` kept by the participant.
    let f = unsafe { &*(ctx as *const F) };
    guarded(f);
}

unsafe extern "C" fn abort_trampoline<F: Fn(ParticipantState) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _ls: *mut raw::LifecycleService,
    last: raw::ParticipantState,
) {
    if ctx.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `F` kept by the participant.
    let f = unsafe { &*(ctx as *const F) };
    guarded(|| f(ParticipantState::from_raw(last)));
}

unsafe extern "C" fn step_trampoline<F: Fn(u64, u64) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _ts: *mut raw::TimeSyncService,
    now: raw::NanosecondsTime,
    duration: raw::NanosecondsTime,
) {
    if ctx.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `F` kept by the participant.
    let f = unsafe { &*(ctx as *const F) };
    guarded(|| f(now, duration));
}

impl Lifecycle {
    fn set(
        &self,
        function: &'static str,
        call: impl FnOnce(&raw::Functions, *mut raw::LifecycleService) -> raw::ReturnCode,
    ) -> Result<(), Error> {
        let ls = self.raw;
        self.inner.call(|api| {
            let rc = call(&api.f, ls);
            api.check(function, rc)
        })?
    }

    /// Call `handler` when communication is ready (the moment to start controllers).
    pub fn on_communication_ready(
        &self,
        handler: impl Fn() + Send + Sync + 'static,
    ) -> Result<(), Error> {
        let (ctx, h) = self.lifecycle_handler(handler);
        self.set(
            "SilKit_LifecycleService_SetCommunicationReadyHandler",
            // SAFETY: a live lifecycle; `ctx` lives as long as the participant.
            |f, ls| unsafe { (f.lifecycle_set_communication_ready_handler)(ls, ctx, h) },
        )
    }

    /// Call `handler` when the simulation stops.
    pub fn on_stop(&self, handler: impl Fn() + Send + Sync + 'static) -> Result<(), Error> {
        let (ctx, h) = self.lifecycle_handler(handler);
        self.set(
            "SilKit_LifecycleService_SetStopHandler",
            // SAFETY: as above.
            |f, ls| unsafe { (f.lifecycle_set_stop_handler)(ls, ctx, h) },
        )
    }

    /// Call `handler` when the participant shuts down.
    pub fn on_shutdown(&self, handler: impl Fn() + Send + Sync + 'static) -> Result<(), Error> {
        let (ctx, h) = self.lifecycle_handler(handler);
        self.set(
            "SilKit_LifecycleService_SetShutdownHandler",
            // SAFETY: as above.
            |f, ls| unsafe { (f.lifecycle_set_shutdown_handler)(ls, ctx, h) },
        )
    }

    /// Call `handler` when the simulation is aborted, with the state it was in.
    pub fn on_abort(
        &self,
        handler: impl Fn(ParticipantState) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        let h = abort_tramp_for(&handler);
        let ctx = self.inner.keep(handler);
        self.set(
            "SilKit_LifecycleService_SetAbortHandler",
            // SAFETY: as above.
            |f, ls| unsafe { (f.lifecycle_set_abort_handler)(ls, ctx, h) },
        )
    }

    fn lifecycle_handler<F: Fn() + Send + Sync + 'static>(
        &self,
        handler: F,
    ) -> (*mut c_void, raw::LifecycleHandler) {
        let h: raw::LifecycleHandler = lifecycle_trampoline::<F>;
        (self.inner.keep(handler), h)
    }

    /// Start the lifecycle (returns at once; handlers run on SIL Kit's thread).
    pub fn start(&self) -> Result<(), Error> {
        // SAFETY: a live lifecycle.
        self.set("SilKit_LifecycleService_StartLifecycle", |f, ls| unsafe {
            (f.lifecycle_start)(ls)
        })
    }

    /// Stop the simulation (the participant must be running).
    pub fn stop(&self, reason: &str) -> Result<(), Error> {
        let c_reason = cstring("stop reason", reason)?;
        // SAFETY: a live lifecycle; the reason lives across the call.
        self.set("SilKit_LifecycleService_Stop", |f, ls| unsafe {
            (f.lifecycle_stop)(ls, c_reason.as_ptr())
        })
    }

    /// The participant's state now.
    pub fn state(&self) -> Result<ParticipantState, Error> {
        let mut s: raw::ParticipantState = 0;
        let ls = self.raw;
        self.inner.call(|api| {
            // SAFETY: a live lifecycle and a valid out-pointer.
            let rc = unsafe { (api.f.lifecycle_state)(&mut s, ls) };
            api.check("SilKit_LifecycleService_State", rc)
        })??;
        Ok(ParticipantState::from_raw(s))
    }

    /// Create the time synchronisation service (before [`Lifecycle::start`]); without it the
    /// participant runs unsynchronised.
    pub fn time_sync(&self) -> Result<TimeSync, Error> {
        let mut ts: *mut raw::TimeSyncService = core::ptr::null_mut();
        let ls = self.raw;
        self.inner.call(|api| {
            // SAFETY: a live lifecycle and a valid out-pointer.
            let rc = unsafe { (api.f.time_sync_create)(&mut ts, ls) };
            api.check("SilKit_TimeSyncService_Create", rc)
        })??;
        Ok(TimeSync {
            inner: Arc::clone(&self.inner),
            raw: ts,
        })
    }
}

/// The abort trampoline of a closure type.
fn abort_tramp_for<F: Fn(ParticipantState) + Send + Sync + 'static>(_: &F) -> raw::AbortHandler {
    abort_trampoline::<F>
}

/// The system monitor of a participant (`SilKit_SystemMonitor`). Cheap to clone.
#[derive(Clone)]
pub struct SystemMonitor {
    inner: Arc<Inner>,
    raw: *mut raw::SystemMonitor,
}

// SAFETY: see `Inner`.
unsafe impl Send for SystemMonitor {}
// SAFETY: as above.
unsafe impl Sync for SystemMonitor {}

impl core::fmt::Debug for SystemMonitor {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SystemMonitor").finish_non_exhaustive()
    }
}

unsafe extern "C" fn status_trampoline<F: Fn(&str, ParticipantState) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _monitor: *mut raw::SystemMonitor,
    name: *const c_char,
    status: *mut raw::ParticipantStatus,
) {
    if ctx.is_null() || name.is_null() || status.is_null() {
        return;
    }
    // SAFETY: `ctx` is the `F` kept by the participant; the name and status are valid
    // during the call and copied here.
    let (f, name, state) = unsafe {
        (
            &*(ctx as *const F),
            CStr::from_ptr(name).to_string_lossy().into_owned(),
            (*status).participant_state,
        )
    };
    guarded(|| f(&name, ParticipantState::from_raw(state)));
}

unsafe extern "C" fn disconnected_trampoline<F: Fn(&str) + Send + Sync + 'static>(
    ctx: *mut c_void,
    _monitor: *mut raw::SystemMonitor,
    info: *const raw::ParticipantConnectionInformation,
) {
    if ctx.is_null() || info.is_null() {
        return;
    }
    // SAFETY: as in `status_trampoline`.
    let (f, name) = unsafe { (&*(ctx as *const F), (*info).participant_name) };
    if name.is_null() {
        return;
    }
    // SAFETY: a NUL-terminated string valid during the call, copied.
    let name = unsafe { CStr::from_ptr(name) }
        .to_string_lossy()
        .into_owned();
    guarded(|| f(&name));
}

impl SystemMonitor {
    /// Call `handler(name, state)` whenever a participant's state changes (this one's too).
    pub fn on_participant_status(
        &self,
        handler: impl Fn(&str, ParticipantState) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        let h = status_tramp_for(&handler);
        let ctx = self.inner.keep(handler);
        let m = self.raw;
        self.inner.call(|api| {
            let mut id = 0;
            // SAFETY: a live monitor; `ctx` lives as long as the participant.
            let rc = unsafe {
                (api.f.system_monitor_add_participant_status_handler)(m, ctx, h, &mut id)
            };
            api.check("SilKit_SystemMonitor_AddParticipantStatusHandler", rc)
        })?
    }

    /// Call `handler(name)` whenever another participant disconnects (leaves or dies).
    pub fn on_participant_disconnected(
        &self,
        handler: impl Fn(&str) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        let h = disconnected_tramp_for(&handler);
        let ctx = self.inner.keep(handler);
        let m = self.raw;
        self.inner.call(|api| {
            // SAFETY: a live monitor; `ctx` lives as long as the participant.
            let rc =
                unsafe { (api.f.system_monitor_set_participant_disconnected_handler)(m, ctx, h) };
            api.check("SilKit_SystemMonitor_SetParticipantDisconnectedHandler", rc)
        })?
    }
}

fn status_tramp_for<F: Fn(&str, ParticipantState) + Send + Sync + 'static>(
    _: &F,
) -> raw::ParticipantStatusHandler {
    status_trampoline::<F>
}

fn disconnected_tramp_for<F: Fn(&str) + Send + Sync + 'static>(
    _: &F,
) -> raw::ParticipantDisconnectedHandler {
    disconnected_trampoline::<F>
}

/// The time synchronisation service (`SilKit_TimeSyncService`). Cheap to clone.
#[derive(Clone)]
pub struct TimeSync {
    inner: Arc<Inner>,
    raw: *mut raw::TimeSyncService,
}

// SAFETY: see `Inner`.
unsafe impl Send for TimeSync {}
// SAFETY: as above.
unsafe impl Sync for TimeSync {}

impl core::fmt::Debug for TimeSync {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("TimeSync").finish_non_exhaustive()
    }
}

impl TimeSync {
    /// Run `handler(now_ns, duration_ns)` for every simulation step of `step_ns`; the step
    /// covers `[now, now + duration)` and ends when the handler returns (the blocking form,
    /// `SilKit_TimeSyncService_SetSimulationStepHandler`). Frames sent in the handler carry
    /// `now`.
    pub fn on_step(
        &self,
        step_ns: u64,
        handler: impl Fn(u64, u64) + Send + Sync + 'static,
    ) -> Result<(), Error> {
        let h = step_tramp_for(&handler);
        let ctx = self.inner.keep(handler);
        let ts = self.raw;
        self.inner.call(|api| {
            // SAFETY: a live service; `ctx` lives as long as the participant.
            let rc = unsafe { (api.f.time_sync_set_step_handler)(ts, ctx, h, step_ns) };
            api.check("SilKit_TimeSyncService_SetSimulationStepHandler", rc)
        })?
    }

    /// The participant's virtual time now, in nanoseconds.
    pub fn now(&self) -> Result<u64, Error> {
        let mut t = 0;
        let ts = self.raw;
        self.inner.call(|api| {
            // SAFETY: a live service and a valid out-pointer.
            let rc = unsafe { (api.f.time_sync_now)(ts, &mut t) };
            api.check("SilKit_TimeSyncService_Now", rc)
        })??;
        Ok(t)
    }
}

fn step_tramp_for<F: Fn(u64, u64) + Send + Sync + 'static>(_: &F) -> raw::StepHandler {
    step_trampoline::<F>
}

/// A CAN network simulated by this participant (SIL Kit's experimental network simulator
/// API, `capi/NetworkSimulator.h`): SIL Kit calls it for every controller on the network, on
/// its communication thread, and it answers through the [`CanEventProducer`] it is handed.
pub trait SimulatedCanNetwork: Send + Sync + 'static {
    /// A controller appeared on the network (`ProvideSimulatedController`); descriptors are
    /// unique and start at 1.
    fn controller_added(&self, descriptor: u64);
    /// The participant owning a controller left (`SimulatedControllerRemoved`).
    fn controller_removed(&self, descriptor: u64);
    /// How to send events to the controllers (`SetEventProducer`, once).
    fn event_producer(&self, producer: CanEventProducer);
    /// `SilKit_CanController_SetBaudRate` of a controller.
    fn baud_rate(&self, descriptor: u64, rate: u32, fd_rate: u32, xl_rate: u32);
    /// `SilKit_CanController_SendFrame` of a controller.
    fn frame_request(&self, descriptor: u64, frame: CanFrame, user_context: usize);
    /// `Start`, `Stop`, `Sleep` or `Reset` of a controller: the requested state, whether the
    /// error counters are to be reset and whether pending transmissions are cancelled.
    fn controller_mode(
        &self,
        descriptor: u64,
        state: ControllerState,
        reset_error_handling: bool,
        cancel_transmit_requests: bool,
    );
}

/// `SilKit_Experimental_NetSim_CanControllerModeFlags`: bit 0 resets error handling, bit 1
/// cancels transmit requests.
const MODE_RESET_ERROR_HANDLING: i32 = 1;
const MODE_CANCEL_TRANSMIT_REQUESTS: i32 = 2;

/// What SIL Kit gets as a simulated network's context.
struct NetworkContext {
    network: Arc<dyn SimulatedCanNetwork>,
    inner: Arc<Inner>,
    produce: ProduceFn,
}

type ProduceFn = unsafe extern "C" fn(
    *mut raw::CanEventProducer,
    *const raw::StructHeader,
    *const raw::EventReceivers,
) -> raw::ReturnCode;

/// What SIL Kit gets as a simulated controller's context.
struct ControllerContext {
    network: Arc<dyn SimulatedCanNetwork>,
    descriptor: u64,
}

/// The network function table; SIL Kit keeps a pointer to it, so it is static.
static NETWORK_FUNCTIONS: raw::SimulatedNetworkFunctions = raw::SimulatedNetworkFunctions {
    header: raw::StructHeader::new(raw::SIMULATED_NETWORK_FUNCTIONS_ID),
    provide_simulated_controller: provide_controller,
    simulated_controller_removed: controller_removed,
    set_event_producer,
};

/// The CAN controller function table, static for the same reason.
static CAN_CONTROLLER_FUNCTIONS: raw::SimulatedCanControllerFunctions =
    raw::SimulatedCanControllerFunctions {
        header: raw::StructHeader::new(raw::SIMULATED_CAN_CONTROLLER_FUNCTIONS_ID),
        on_set_baudrate,
        on_frame_request,
        on_set_controller_mode,
    };

unsafe extern "C" fn provide_controller(
    out_controller: *mut *mut c_void,
    out_functions: *mut *const c_void,
    descriptor: u64,
    network: *mut c_void,
) {
    if out_controller.is_null() || out_functions.is_null() || network.is_null() {
        return;
    }
    // SAFETY: `network` is the `NetworkContext` kept by the participant.
    let net = unsafe { &*(network as *const NetworkContext) };
    let ctx = net.inner.keep(ControllerContext {
        network: Arc::clone(&net.network),
        descriptor,
    });
    // SAFETY: valid out-pointers; the controller context lives as long as the participant
    // and the function table is static (SIL Kit stores both pointers).
    unsafe {
        *out_controller = ctx;
        *out_functions = &CAN_CONTROLLER_FUNCTIONS as *const _ as *const c_void;
    }
    guarded(|| net.network.controller_added(descriptor));
}

unsafe extern "C" fn controller_removed(descriptor: u64, network: *mut c_void) {
    if network.is_null() {
        return;
    }
    // SAFETY: `network` is the `NetworkContext` kept by the participant.
    let net = unsafe { &*(network as *const NetworkContext) };
    guarded(|| net.network.controller_removed(descriptor));
}

unsafe extern "C" fn set_event_producer(producer: *mut c_void, network: *mut c_void) {
    if producer.is_null() || network.is_null() {
        return;
    }
    // SAFETY: `network` is the `NetworkContext` kept by the participant.
    let net = unsafe { &*(network as *const NetworkContext) };
    let producer = CanEventProducer {
        inner: Arc::clone(&net.inner),
        raw: producer,
        produce: net.produce,
    };
    guarded(|| net.network.event_producer(producer));
}

unsafe extern "C" fn on_set_baudrate(
    controller: *mut c_void,
    msg: *const raw::NetSimCanConfigureBaudrate,
) {
    if controller.is_null() || msg.is_null() {
        return;
    }
    // SAFETY: `controller` is a `ControllerContext` kept by the participant; `msg` is valid
    // during the call.
    let (c, m) = unsafe { (&*(controller as *const ControllerContext), &*msg) };
    let (rate, fd, xl) = (m.rate, m.fd_rate, m.xl_rate);
    guarded(|| c.network.baud_rate(c.descriptor, rate, fd, xl));
}

unsafe extern "C" fn on_frame_request(
    controller: *mut c_void,
    msg: *const raw::NetSimCanFrameRequest,
) {
    if controller.is_null() || msg.is_null() {
        return;
    }
    // SAFETY: as in `on_set_baudrate`; the frame is on SIL Kit's stack and copied here.
    let (c, m) = unsafe { (&*(controller as *const ControllerContext), &*msg) };
    // SAFETY: the frame pointer of a valid request.
    let Some(frame) = (unsafe { copy_frame(m.frame) }) else {
        return;
    };
    let tag = m.user_context as usize;
    guarded(|| c.network.frame_request(c.descriptor, frame, tag));
}

unsafe extern "C" fn on_set_controller_mode(
    controller: *mut c_void,
    msg: *const raw::NetSimCanControllerMode,
) {
    if controller.is_null() || msg.is_null() {
        return;
    }
    // SAFETY: as in `on_set_baudrate`.
    let (c, m) = unsafe { (&*(controller as *const ControllerContext), &*msg) };
    let flags = m.can_controller_mode_flags;
    let state = ControllerState::from_raw(m.state);
    guarded(|| {
        c.network.controller_mode(
            c.descriptor,
            state,
            flags & MODE_RESET_ERROR_HANDLING != 0,
            flags & MODE_CANCEL_TRANSMIT_REQUESTS != 0,
        )
    });
}

/// Sends simulated events to controllers (`SilKit_Experimental_CanEventProducer_Produce`).
/// Cheap to clone.
#[derive(Clone)]
pub struct CanEventProducer {
    inner: Arc<Inner>,
    raw: *mut raw::CanEventProducer,
    produce: ProduceFn,
}

// SAFETY: see `Inner`; the producer is owned by the participant's network simulator.
unsafe impl Send for CanEventProducer {}
// SAFETY: as above.
unsafe impl Sync for CanEventProducer {}

impl core::fmt::Debug for CanEventProducer {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("CanEventProducer").finish_non_exhaustive()
    }
}

impl CanEventProducer {
    fn send(&self, header: *const raw::StructHeader, receivers: &[u64]) -> Result<(), Error> {
        let rx = raw::EventReceivers {
            header: raw::StructHeader::new(raw::EVENT_RECEIVERS_ID),
            num_receivers: receivers.len(),
            controller_descriptors: receivers.as_ptr(),
        };
        let (p, produce) = (self.raw, self.produce);
        self.inner.call(|api| {
            // SAFETY: the producer of a live participant; the event and the receiver list
            // live across the call.
            let rc = unsafe { produce(p, header, &rx) };
            api.check("SilKit_Experimental_CanEventProducer_Produce", rc)
        })?
    }

    /// Deliver a frame to `receivers` (controller descriptors).
    pub fn frame(&self, event: &FrameEvent, receivers: &[u64]) -> Result<(), Error> {
        let mut frame = c_frame(&event.frame);
        let ev = raw::CanFrameEvent {
            header: raw::StructHeader::new(raw::CAN_FRAME_EVENT_ID),
            timestamp: event.timestamp,
            frame: &mut frame,
            direction: match event.direction {
                Direction::Send => 1,
                Direction::Receive => 2,
            },
            user_context: event.user_context as *mut c_void,
        };
        self.send(&ev.header, receivers)
    }

    /// Deliver a transmit acknowledgement to `receivers`.
    pub fn transmit(&self, event: &TransmitEvent, receivers: &[u64]) -> Result<(), Error> {
        let ev = raw::CanFrameTransmitEvent {
            header: raw::StructHeader::new(raw::CAN_FRAME_TRANSMIT_EVENT_ID),
            user_context: event.user_context as *mut c_void,
            timestamp: event.timestamp,
            status: event.status.raw(),
            can_id: event.can_id,
        };
        self.send(&ev.header, receivers)
    }

    /// Deliver a controller state change to `receivers`.
    pub fn state(&self, event: &StateChangeEvent, receivers: &[u64]) -> Result<(), Error> {
        let ev = raw::CanStateChangeEvent {
            header: raw::StructHeader::new(raw::CAN_STATE_CHANGE_EVENT_ID),
            timestamp: event.timestamp,
            state: event.state.raw(),
        };
        self.send(&ev.header, receivers)
    }

    /// Deliver an error state change to `receivers`.
    pub fn error_state(
        &self,
        event: &ErrorStateChangeEvent,
        receivers: &[u64],
    ) -> Result<(), Error> {
        let ev = raw::CanErrorStateChangeEvent {
            header: raw::StructHeader::new(raw::CAN_ERROR_STATE_CHANGE_EVENT_ID),
            timestamp: event.timestamp,
            error_state: event.error_state.raw(),
        };
        self.send(&ev.header, receivers)
    }
}

impl Participant {
    /// Act as the network simulator of the CAN networks `networks` (name and model). Call
    /// before the lifecycle starts: it blocks until every connected participant has answered
    /// (`SilKit_Experimental_NetworkSimulator_Start`, which detects a second simulator).
    pub fn simulate_can_networks(
        &self,
        networks: &[(&str, Arc<dyn SimulatedCanNetwork>)],
    ) -> Result<(), Error> {
        let f = &self.inner.api.f;
        let create = f.network_simulator_create.ok_or(Error::NoExperimental(
            "SilKit_Experimental_NetworkSimulator_Create",
        ))?;
        let simulate = f
            .network_simulator_simulate_network
            .ok_or(Error::NoExperimental(
                "SilKit_Experimental_NetworkSimulator_SimulateNetwork",
            ))?;
        let start = f.network_simulator_start.ok_or(Error::NoExperimental(
            "SilKit_Experimental_NetworkSimulator_Start",
        ))?;
        let produce = f.can_event_producer_produce.ok_or(Error::NoExperimental(
            "SilKit_Experimental_CanEventProducer_Produce",
        ))?;
        let p = self.inner.raw;
        let mut ns: *mut raw::NetworkSimulator = core::ptr::null_mut();
        self.inner.call(|api| {
            // SAFETY: the participant is alive; the simulator is owned by it.
            let rc = unsafe { create(&mut ns, p) };
            api.check("SilKit_Experimental_NetworkSimulator_Create", rc)
        })??;
        for (name, network) in networks {
            let c_name = cstring("network name", name)?;
            let ctx = self.inner.keep(NetworkContext {
                network: Arc::clone(network),
                inner: Arc::clone(&self.inner),
                produce,
            });
            self.inner.call(|api| {
                // SAFETY: `ctx` lives as long as the participant; the table is static.
                let rc = unsafe {
                    simulate(
                        ns,
                        c_name.as_ptr(),
                        raw::NETWORK_TYPE_CAN,
                        ctx,
                        &NETWORK_FUNCTIONS,
                    )
                };
                api.check("SilKit_Experimental_NetworkSimulator_SimulateNetwork", rc)
            })??;
        }
        self.inner.call(|api| {
            // SAFETY: the simulator of this live participant.
            let rc = unsafe { start(ns) };
            api.check("SilKit_Experimental_NetworkSimulator_Start", rc)
        })?
    }
}
