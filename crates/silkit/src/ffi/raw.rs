//! The subset of SIL Kit's C API (`silkit/capi/*.h`, SIL Kit 5.0) that cantwin uses, declared
//! from the public headers: the structure layouts (packed to 8, i.e. natural alignment, so
//! `repr(C)` matches), the constants, and the function signatures of the symbols looked up
//! in `libSilKit.so`. On Linux `SilKitCALL` is the C calling convention.

use core::ffi::{c_char, c_void};

/// `SilKit_ReturnCode` (`capi/Types.h`).
pub type ReturnCode = i32;
/// `SilKit_ReturnCode` SUCCESS.
pub const SUCCESS: ReturnCode = 0;
/// `SilKit_NanosecondsTime`: virtual time in nanoseconds.
pub type NanosecondsTime = u64;
/// `SilKit_HandlerId`.
pub type HandlerId = u64;
/// `SilKit_ParticipantState` (also `SilKit_SystemState`).
pub type ParticipantState = i16;

/// Opaque handles: only ever held by pointer.
pub type Participant = c_void;
/// `SilKit_ParticipantConfiguration`.
pub type ParticipantConfiguration = c_void;
/// `SilKit_CanController`.
pub type CanController = c_void;
/// `SilKit_LifecycleService`.
pub type LifecycleService = c_void;
/// `SilKit_TimeSyncService`.
pub type TimeSyncService = c_void;
/// `SilKit_SystemMonitor`.
pub type SystemMonitor = c_void;
/// `SilKit_Experimental_SystemController`.
pub type SystemController = c_void;
/// `SilKit_Experimental_NetworkSimulator`.
pub type NetworkSimulator = c_void;
/// `SilKit_Experimental_CanEventProducer`.
pub type CanEventProducer = c_void;

/// `SilKit_StructHeader` (`capi/InterfaceIdentifiers.h`): every versioned structure starts
/// with it; the library rejects a structure whose header it does not know.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct StructHeader {
    pub version: u64,
    pub reserved: [u64; 3],
}

/// `SK_ID_MAKE(service, datatype)`: 'S' 'K', service, datatype id, datatype version.
pub const fn struct_id(service: u8, datatype: u8, version: u8) -> u64 {
    (0x53 << 56)
        | (0x4B << 48)
        | ((service as u64) << 40)
        | ((datatype as u64) << 32)
        | ((version as u64) << 24)
}

impl StructHeader {
    pub const fn new(version: u64) -> Self {
        StructHeader {
            version,
            reserved: [0; 3],
        }
    }

    /// The structure version of a header (bits 24-31).
    pub const fn struct_version(self) -> u8 {
        (self.version >> 24) as u8
    }
}

const SERVICE_CAN: u8 = 1;
const SERVICE_PARTICIPANT: u8 = 7;

pub const CAN_FRAME_ID: u64 = struct_id(SERVICE_CAN, 1, 1);
pub const LIFECYCLE_CONFIGURATION_ID: u64 = struct_id(SERVICE_PARTICIPANT, 2, 1);
pub const WORKFLOW_CONFIGURATION_ID: u64 = struct_id(SERVICE_PARTICIPANT, 3, 3);
const SERVICE_NETSIM: u8 = 8;
pub const CAN_FRAME_TRANSMIT_EVENT_ID: u64 = struct_id(SERVICE_CAN, 2, 2);
pub const CAN_FRAME_EVENT_ID: u64 = struct_id(SERVICE_CAN, 3, 1);
pub const CAN_STATE_CHANGE_EVENT_ID: u64 = struct_id(SERVICE_CAN, 4, 1);
pub const CAN_ERROR_STATE_CHANGE_EVENT_ID: u64 = struct_id(SERVICE_CAN, 5, 1);
pub const EVENT_RECEIVERS_ID: u64 = struct_id(SERVICE_NETSIM, 1, 1);
pub const SIMULATED_NETWORK_FUNCTIONS_ID: u64 = struct_id(SERVICE_NETSIM, 2, 1);
pub const SIMULATED_CAN_CONTROLLER_FUNCTIONS_ID: u64 = struct_id(SERVICE_NETSIM, 3, 1);

/// `SilKit_Experimental_SimulatedNetworkType` CAN.
pub const NETWORK_TYPE_CAN: u32 = 1;

/// `SilKit_ByteVector`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct ByteVector {
    pub data: *const u8,
    pub size: usize,
}

/// `SilKit_StringList`.
#[repr(C)]
pub struct StringList {
    pub num_strings: usize,
    pub strings: *mut *mut c_char,
}

/// `SilKit_CanFrame` (`capi/Can.h`).
#[repr(C)]
#[derive(Clone, Copy)]
pub struct CanFrame {
    pub header: StructHeader,
    pub id: u32,
    pub flags: u32,
    pub dlc: u16,
    pub sdt: u8,
    pub vcid: u8,
    pub af: u32,
    pub data: ByteVector,
}

/// `SilKit_CanFrameEvent`.
#[repr(C)]
pub struct CanFrameEvent {
    pub header: StructHeader,
    pub timestamp: NanosecondsTime,
    pub frame: *mut CanFrame,
    pub direction: u8,
    pub user_context: *mut c_void,
}

/// `SilKit_CanFrameTransmitEvent` (version 2, with `canId`).
#[repr(C)]
pub struct CanFrameTransmitEvent {
    pub header: StructHeader,
    pub user_context: *mut c_void,
    pub timestamp: NanosecondsTime,
    pub status: i32,
    pub can_id: u32,
}

/// `SilKit_CanStateChangeEvent`.
#[repr(C)]
pub struct CanStateChangeEvent {
    pub header: StructHeader,
    pub timestamp: NanosecondsTime,
    pub state: i32,
}

/// `SilKit_CanErrorStateChangeEvent`.
#[repr(C)]
pub struct CanErrorStateChangeEvent {
    pub header: StructHeader,
    pub timestamp: NanosecondsTime,
    pub error_state: i32,
}

/// `SilKit_LifecycleConfiguration` (`capi/Orchestration.h`).
#[repr(C)]
pub struct LifecycleConfiguration {
    pub header: StructHeader,
    pub operation_mode: i8,
}

/// `SilKit_ParticipantStatus` (`capi/Orchestration.h`).
#[repr(C)]
pub struct ParticipantStatus {
    pub header: StructHeader,
    pub participant_name: *const c_char,
    pub participant_state: ParticipantState,
    pub enter_reason: *const c_char,
    pub enter_time: u64,
    pub refresh_time: u64,
}

/// `SilKit_ParticipantConnectionInformation`.
#[repr(C)]
pub struct ParticipantConnectionInformation {
    pub header: StructHeader,
    pub participant_name: *const c_char,
}

/// `SilKit_WorkflowConfiguration`.
#[repr(C)]
pub struct WorkflowConfiguration {
    pub header: StructHeader,
    pub required_participant_names: *mut StringList,
}

/// `SilKit_Experimental_EventReceivers` (`capi/EventProducer.h`).
#[repr(C)]
pub struct EventReceivers {
    pub header: StructHeader,
    pub num_receivers: usize,
    pub controller_descriptors: *const u64,
}

/// `SilKit_Experimental_NetSim_CanConfigureBaudrate` (`capi/NetworkSimulator.h`).
#[repr(C)]
pub struct NetSimCanConfigureBaudrate {
    pub header: StructHeader,
    pub rate: u32,
    pub fd_rate: u32,
    pub xl_rate: u32,
}

/// `SilKit_Experimental_NetSim_CanControllerMode`.
#[repr(C)]
pub struct NetSimCanControllerMode {
    pub header: StructHeader,
    pub can_controller_mode_flags: i32,
    pub state: i32,
}

/// `SilKit_Experimental_NetSim_CanFrameRequest`.
#[repr(C)]
pub struct NetSimCanFrameRequest {
    pub header: StructHeader,
    pub frame: *mut CanFrame,
    pub user_context: *mut c_void,
}

/// `SilKit_Experimental_SimulatedNetworkFunctions`.
#[repr(C)]
pub struct SimulatedNetworkFunctions {
    pub header: StructHeader,
    pub provide_simulated_controller: unsafe extern "C" fn(
        out_controller: *mut *mut c_void,
        out_functions: *mut *const c_void,
        descriptor: u64,
        network: *mut c_void,
    ),
    pub simulated_controller_removed: unsafe extern "C" fn(descriptor: u64, network: *mut c_void),
    pub set_event_producer: unsafe extern "C" fn(producer: *mut c_void, network: *mut c_void),
}

/// `SilKit_Experimental_SimulatedCanControllerFunctions`.
#[repr(C)]
pub struct SimulatedCanControllerFunctions {
    pub header: StructHeader,
    pub on_set_baudrate:
        unsafe extern "C" fn(controller: *mut c_void, msg: *const NetSimCanConfigureBaudrate),
    pub on_frame_request:
        unsafe extern "C" fn(controller: *mut c_void, msg: *const NetSimCanFrameRequest),
    pub on_set_controller_mode:
        unsafe extern "C" fn(controller: *mut c_void, msg: *const NetSimCanControllerMode),
}

pub type CanFrameHandler =
    unsafe extern "C" fn(*mut c_void, *mut CanController, *mut CanFrameEvent);
pub type CanFrameTransmitHandler =
    unsafe extern "C" fn(*mut c_void, *mut CanController, *mut CanFrameTransmitEvent);
pub type CanStateChangeHandler =
    unsafe extern "C" fn(*mut c_void, *mut CanController, *mut CanStateChangeEvent);
pub type CanErrorStateChangeHandler =
    unsafe extern "C" fn(*mut c_void, *mut CanController, *mut CanErrorStateChangeEvent);
pub type LifecycleHandler = unsafe extern "C" fn(*mut c_void, *mut LifecycleService);
pub type AbortHandler = unsafe extern "C" fn(*mut c_void, *mut LifecycleService, ParticipantState);
pub type ParticipantStatusHandler =
    unsafe extern "C" fn(*mut c_void, *mut SystemMonitor, *const c_char, *mut ParticipantStatus);
pub type ParticipantDisconnectedHandler =
    unsafe extern "C" fn(*mut c_void, *mut SystemMonitor, *const ParticipantConnectionInformation);
pub type StepHandler =
    unsafe extern "C" fn(*mut c_void, *mut TimeSyncService, NanosecondsTime, NanosecondsTime);

/// The C functions, as looked up by name.
#[allow(clippy::type_complexity)]
pub struct Functions {
    pub version_string: unsafe extern "C" fn(*mut *const c_char) -> ReturnCode,
    pub version_major: unsafe extern "C" fn(*mut u32) -> ReturnCode,
    pub get_last_error_string: unsafe extern "C" fn() -> *const c_char,
    pub return_code_to_string: unsafe extern "C" fn(*mut *const c_char, ReturnCode) -> ReturnCode,
    pub configuration_from_string:
        unsafe extern "C" fn(*mut *mut ParticipantConfiguration, *const c_char) -> ReturnCode,
    pub configuration_destroy: unsafe extern "C" fn(*mut ParticipantConfiguration) -> ReturnCode,
    pub participant_create: unsafe extern "C" fn(
        *mut *mut Participant,
        *mut ParticipantConfiguration,
        *const c_char,
        *const c_char,
    ) -> ReturnCode,
    pub participant_destroy: unsafe extern "C" fn(*mut Participant) -> ReturnCode,
    pub can_create: unsafe extern "C" fn(
        *mut *mut CanController,
        *mut Participant,
        *const c_char,
        *const c_char,
    ) -> ReturnCode,
    pub can_start: unsafe extern "C" fn(*mut CanController) -> ReturnCode,
    pub can_stop: unsafe extern "C" fn(*mut CanController) -> ReturnCode,
    pub can_reset: unsafe extern "C" fn(*mut CanController) -> ReturnCode,
    pub can_send_frame:
        unsafe extern "C" fn(*mut CanController, *mut CanFrame, *mut c_void) -> ReturnCode,
    pub can_set_baud_rate: unsafe extern "C" fn(*mut CanController, u32, u32, u32) -> ReturnCode,
    pub can_add_frame_handler: unsafe extern "C" fn(
        *mut CanController,
        *mut c_void,
        CanFrameHandler,
        u8,
        *mut HandlerId,
    ) -> ReturnCode,
    pub can_add_frame_transmit_handler: unsafe extern "C" fn(
        *mut CanController,
        *mut c_void,
        CanFrameTransmitHandler,
        i32,
        *mut HandlerId,
    ) -> ReturnCode,
    pub can_add_state_change_handler: unsafe extern "C" fn(
        *mut CanController,
        *mut c_void,
        CanStateChangeHandler,
        *mut HandlerId,
    ) -> ReturnCode,
    pub can_add_error_state_change_handler: unsafe extern "C" fn(
        *mut CanController,
        *mut c_void,
        CanErrorStateChangeHandler,
        *mut HandlerId,
    ) -> ReturnCode,
    pub lifecycle_create: unsafe extern "C" fn(
        *mut *mut LifecycleService,
        *mut Participant,
        *const LifecycleConfiguration,
    ) -> ReturnCode,
    pub lifecycle_set_communication_ready_handler:
        unsafe extern "C" fn(*mut LifecycleService, *mut c_void, LifecycleHandler) -> ReturnCode,
    pub lifecycle_set_stop_handler:
        unsafe extern "C" fn(*mut LifecycleService, *mut c_void, LifecycleHandler) -> ReturnCode,
    pub lifecycle_set_shutdown_handler:
        unsafe extern "C" fn(*mut LifecycleService, *mut c_void, LifecycleHandler) -> ReturnCode,
    pub lifecycle_set_abort_handler:
        unsafe extern "C" fn(*mut LifecycleService, *mut c_void, AbortHandler) -> ReturnCode,
    pub lifecycle_start: unsafe extern "C" fn(*mut LifecycleService) -> ReturnCode,
    pub lifecycle_wait:
        unsafe extern "C" fn(*mut LifecycleService, *mut ParticipantState) -> ReturnCode,
    pub lifecycle_stop: unsafe extern "C" fn(*mut LifecycleService, *const c_char) -> ReturnCode,
    pub lifecycle_state:
        unsafe extern "C" fn(*mut ParticipantState, *mut LifecycleService) -> ReturnCode,
    pub time_sync_create:
        unsafe extern "C" fn(*mut *mut TimeSyncService, *mut LifecycleService) -> ReturnCode,
    pub time_sync_set_step_handler: unsafe extern "C" fn(
        *mut TimeSyncService,
        *mut c_void,
        StepHandler,
        NanosecondsTime,
    ) -> ReturnCode,
    pub time_sync_now:
        unsafe extern "C" fn(*mut TimeSyncService, *mut NanosecondsTime) -> ReturnCode,
    pub system_monitor_create:
        unsafe extern "C" fn(*mut *mut SystemMonitor, *mut Participant) -> ReturnCode,
    pub system_monitor_add_participant_status_handler: unsafe extern "C" fn(
        *mut SystemMonitor,
        *mut c_void,
        ParticipantStatusHandler,
        *mut HandlerId,
    ) -> ReturnCode,
    pub system_monitor_set_participant_disconnected_handler: unsafe extern "C" fn(
        *mut SystemMonitor,
        *mut c_void,
        ParticipantDisconnectedHandler,
    )
        -> ReturnCode,
    pub system_controller_create:
        Option<unsafe extern "C" fn(*mut *mut SystemController, *mut Participant) -> ReturnCode>,
    pub system_controller_set_workflow: Option<
        unsafe extern "C" fn(*mut SystemController, *const WorkflowConfiguration) -> ReturnCode,
    >,
    pub network_simulator_create:
        Option<unsafe extern "C" fn(*mut *mut NetworkSimulator, *mut Participant) -> ReturnCode>,
    pub network_simulator_simulate_network: Option<
        unsafe extern "C" fn(
            *mut NetworkSimulator,
            *const c_char,
            u32,
            *mut c_void,
            *const SimulatedNetworkFunctions,
        ) -> ReturnCode,
    >,
    pub network_simulator_start: Option<unsafe extern "C" fn(*mut NetworkSimulator) -> ReturnCode>,
    pub can_event_producer_produce: Option<
        unsafe extern "C" fn(
            *mut CanEventProducer,
            *const StructHeader,
            *const EventReceivers,
        ) -> ReturnCode,
    >,
}
