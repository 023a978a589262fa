//! Deliberately broken CiA 301 devices: a [`Device`] with the communication objects, PDOs,
//! storage and a few application objects, behind a [`Broken`] node that gives it exactly
//! one [`Fault`]: it alters what reaches the device or what the device sends, and nothing
//! else. Without a fault the node passes every frame through untouched, so the unbroken
//! device and each broken one differ in that one behaviour only.
#![allow(dead_code, clippy::unwrap_used)]

use std::sync::Arc;

use cantwin_bus::{BusConfig, BusId, PortConfig, PortId, Simulation};
use cantwin_can::{BitRate, ControllerEvent, Duration, Frame, Id, Instant, Node, Outbox};
use cantwin_canopen::ObjectAccess;
use cantwin_canopen::device::{Device, DeviceConfig};
use cantwin_canopen::nmt::State;
use cantwin_canopen::objects::{Cia301Options, cia301_defaults};
use cantwin_canopen::od::{Access, DataType, OdBuilder, OdDescription, SubObject, Value};
use cantwin_canopen::pdo::PdoObjects;
use cantwin_canopen::sdo::crc::Crc16;
use cantwin_eds::{DeviceInfo, Eds, FileInfo};

/// The one fault of a broken device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// Answers SDO requests in STOPPED (with abort 0x08000022), where CiA 301 §7.3.2.2.5
    /// allows no SDO at all.
    SdoInStopped,
    /// Does not check the toggle bit of segmented transfers (§7.2.4.3.4, §7.2.4.3.7): every
    /// download segment and upload segment request is taken as if its toggle bit were the
    /// expected one, so a wrong toggle is never aborted with 0x05030000.
    ToggleIgnored,
    /// Sends no boot-up message after NMT reset communication (§7.2.8.3.2.1 requires one
    /// after every pass through INITIALISING).
    NoBootUpAfterResetCommunication,
    /// Accepts a write to a PDO mapping parameter while the PDO is valid, where §7.5.2.35 –
    /// §7.5.2.38 require the PDO to be made invalid first (abort otherwise).
    MappingChangeOnValidPdo,
    /// Sends a block upload CRC that is not the CRC of the data (§7.2.4.3.16).
    WrongBlockUploadCrc,
    /// Produces its heartbeat at twice the period 0x1017 sets (§7.2.8.3.2.2): every other
    /// heartbeat is left out.
    HeartbeatAtTwiceThePeriod,
    /// Accepts a new CAN-ID in 0x1014 while the EMCY is valid (bit 31 = 0), which
    /// §7.5.2.17 forbids.
    EmcyCobIdChangeWhileValid,
    /// Stores (0x1010) whatever is written, where §7.5.2.13 requires the signature "save"
    /// and an abort 0x08000020 for anything else.
    StoreWithoutSignature,
    /// Accepts a new CAN-ID in a PDO's COB-ID (sub 1) while the PDO is valid, which
    /// §7.5.2.35 – §7.5.2.38 forbid.
    PdoCobIdChangeWhileValid,
    /// Answers a write of a value other than 0 to 0x1003 sub 0 as a success (and ignores
    /// it), where §7.5.2.4 allows only 0 and requires abort 0x06090030 otherwise.
    ErrorHistoryWriteAccepted,
    /// Does not check the CRC of a block download (§7.2.4.3.11): the end request reaches
    /// the device with the CRC of the data it took, so a wrong one is never aborted with
    /// 0x05040004.
    BlockDownloadCrcNotChecked,
    /// Takes a second 0x1016 entry for a node-ID another entry monitors already, where
    /// §7.5.2.19 requires abort 0x06040043.
    DuplicateHeartbeatConsumerAccepted,
    /// Sends TPDO 1 on its event timer in PRE-OPERATIONAL too, where §7.3.2.2.5
    /// allows PDOs only in OPERATIONAL.
    TpdoInPreOperational,
    /// Answers every block upload initiate with an ordinary (expedited or segmented)
    /// upload, as a server without block upload might, although the client's protocol
    /// switch threshold pst = 0 allows no change of protocol (§7.2.4.3.13).
    BlockUploadSwitchedOnPst0,
    /// Never sends a TPDO whose transmission type is 0, where §7.2.2.2.2 requires it on
    /// the SYNC after an event of the device (a change of a mapped value).
    AcyclicTpdoNeverSent,
    /// Does not answer a write of a new CAN-ID to a valid PDO's COB-ID (sub 1), where
    /// §7.5.2.35 – §7.5.2.38 require the server to refuse it with an abort.
    PdoCobIdChangeWhileValidUnanswered,
    /// Ignores NMT reset node and reset communication in STOPPED, where §7.3.2.2.1
    /// (figure 48) has both lead from every state through INITIALISATION to
    /// PRE-OPERATIONAL.
    ResetIgnoredInStopped,
    /// Reports OPERATIONAL (5) in its first heartbeat or guarding answer after a boot-up,
    /// where §7.3.2.2.1 has INITIALISATION end in PRE-OPERATIONAL (127).
    OperationalReportedAfterBootUp,
    /// Processes RPDO 1 in STOPPED, where §7.3.2.2.5 allows PDOs only in OPERATIONAL.
    RpdoProcessedInStopped,
    /// Processes RPDO 1 in PRE-OPERATIONAL, where §7.3.2.2.5 allows PDOs only in
    /// OPERATIONAL.
    RpdoProcessedInPreOperational,
    /// Sends TPDO 1 on each SYNC in STOPPED when its type is synchronous (1–240), where
    /// §7.3.2.2.5 allows PDOs only in OPERATIONAL.
    SyncTpdoInStopped,
    /// Sends the RPDO length EMCY (0x8210) for a short RPDO 1 in STOPPED too, where
    /// §7.3.2.2.5 allows no EMCY in STOPPED.
    EmcyInStopped,
    /// Sends TPDO 1 at every SYNC when its type is 3–240, where §7.5.2.37 table 71 has
    /// type n send it at every n-th SYNC.
    CyclicTypeAtEverySync,
    /// Sends TPDO 1 at every SYNC at type 252, where §7.5.2.37 table 71 has it sent only
    /// on a remote frame.
    RtrSyncTypeSentOnSync,
    /// Takes the reserved transmission types 241–251 in 0x1800 sub 2, where §7.5.2.37
    /// table 71 reserves them (the write must be refused with an abort).
    ReservedTransmissionTypeAccepted,
    /// Does not check the toggle bit of upload segment requests (§7.2.4.3.7): each is
    /// taken as if it carried the expected toggle, so a wrong one is never aborted with
    /// 0x05030000. Download segments are checked.
    UploadToggleIgnored,
    /// Sends block-upload sub-blocks of 127 segments whatever valid block size the client asks
    /// for, where §7.2.4.3.12 – §7.2.4.3.14 have the server send at most `blksize` segments
    /// before the client's acknowledgement.
    BlockUploadBlockSizeIgnored,
    /// Answers a block download initiate with block size 0, outside the 1..=127 that
    /// §7.2.4.3.9 allows.
    BlockDownloadBlockSizeZero,
    /// Refuses a block download initiate without size indication (s = 0) with 0x06070010,
    /// where §7.2.4.3.9 makes the size indication optional for the client.
    BlockDownloadWithoutSizeRefused,
    /// Answers an upload of the write-only entry [`WRITE_ONLY_INDEX`] with data, where
    /// §7.2.4.3.17 requires abort 0x06010001.
    WriteOnlyEntryRead,
    /// Takes a value below the low limit of [`OFFSET_INDEX`] (the write is answered as a
    /// success and ignored), where §7.2.4.3.17 requires abort 0x06090032 (or 0x06090030).
    LowLimitNotChecked,
    /// Takes a write to a mapping entry of an invalid PDO while sub-index 0 is not 0 (by
    /// disabling the mapping behind the client's back), where §7.5.2.36 and §7.5.2.38 allow
    /// entries to change only while sub-index 0 is 0.
    MappingEntryWrittenWhileEnabled,
    /// Answers a sub-index 0 write that enables a mapping of more than 64 bits as a
    /// success (and ignores it), where §7.5.2.36 and §7.5.2.38 require abort 0x06040042.
    MappingLengthNotChecked,
    /// Answers a mapping entry naming an object that cannot be mapped as a success (and
    /// ignores it), where §7.5.2.36 and §7.5.2.38 require abort 0x06040041.
    NotMappableObjectMapped,
    /// Answers a mapping entry naming an object that does not exist as a success (and
    /// ignores it), where §7.5.2.36 and §7.5.2.38 require abort 0x06020000.
    AbsentObjectMapped,
    /// Sends TPDO 1 with its power-on mapping (0x2100 sub 1 and 2) whatever mapping it was
    /// given, where §7.5.2.38 has the PDO carry the objects its mapping names.
    OldMappingSent,
    /// Answers an upload of 0x1003 sub 0 with 0 whatever errors it recorded, where
    /// §7.5.2.4 has sub 0 count the errors and sub 1 hold the newest.
    ErrorHistoryNotCounted,
    /// Answers a write of 0x1012 with bit 30 (produce TIME) as a success and ignores it,
    /// where §7.5.2.15 requires the producer or abort 0x06090030.
    TimeProducerBitIgnored,
    /// Answers a write of 0x1012 with bit 31 (consume TIME) as a success and ignores it
    /// (§7.5.2.15).
    TimeConsumerBitIgnored,
    /// Answers "load" to 0x1011 sub 2 as a success and restores nothing, where §7.5.2.14
    /// has the communication parameters' defaults take effect at the next reset
    /// communication.
    RestoreCommunicationIgnored,
    /// Sets the application parameter [`SET_POINT_INDEX`] to its default at reset
    /// communication, where §7.3.2.2.1 has reset communication set only the communication
    /// area to its power-on values (the application area waits for reset node).
    ResetCommunicationResetsApplication,
    /// Ignores every RPDO in OPERATIONAL, where §7.2.2 and §7.3.2.2.5 have an RPDO
    /// received in OPERATIONAL write the objects its mapping names.
    RpdoIgnoredInOperational,
    /// Obeys an NMT command whatever node-ID it carries, where §7.2.8.3.1 has the
    /// command's node-ID select the node (0: all nodes).
    NmtForAnyNodeId,
    /// Answers an upload of the error register 0x1001 with 0 whatever errors stand, where
    /// §7.5.2.2 has bit 0 set at any error (and §7.2.7.1 the EMCY carry 0x1001).
    ErrorRegisterReadsZero,
    /// Leaves out the EMCY with error code 0x0000 that §7.2.7.1 has the device send when
    /// an error is reset.
    NoErrorResetEmcy,
    /// Sends only the first EMCY after an inhibit time was set (0x1015 ≠ 0) and drops
    /// every later one, where §7.2.7.1 and §7.5.2.18 have the inhibit time delay an EMCY,
    /// not suppress it.
    InhibitedEmcyDropped,
}

impl Fault {
    /// Every fault.
    pub const ALL: [Fault; 46] = [
        Fault::SdoInStopped,
        Fault::ToggleIgnored,
        Fault::NoBootUpAfterResetCommunication,
        Fault::MappingChangeOnValidPdo,
        Fault::WrongBlockUploadCrc,
        Fault::HeartbeatAtTwiceThePeriod,
        Fault::EmcyCobIdChangeWhileValid,
        Fault::StoreWithoutSignature,
        Fault::PdoCobIdChangeWhileValid,
        Fault::ErrorHistoryWriteAccepted,
        Fault::BlockDownloadCrcNotChecked,
        Fault::DuplicateHeartbeatConsumerAccepted,
        Fault::TpdoInPreOperational,
        Fault::BlockUploadSwitchedOnPst0,
        Fault::AcyclicTpdoNeverSent,
        Fault::PdoCobIdChangeWhileValidUnanswered,
        Fault::ResetIgnoredInStopped,
        Fault::OperationalReportedAfterBootUp,
        Fault::RpdoProcessedInStopped,
        Fault::RpdoProcessedInPreOperational,
        Fault::SyncTpdoInStopped,
        Fault::EmcyInStopped,
        Fault::CyclicTypeAtEverySync,
        Fault::RtrSyncTypeSentOnSync,
        Fault::ReservedTransmissionTypeAccepted,
        Fault::UploadToggleIgnored,
        Fault::BlockUploadBlockSizeIgnored,
        Fault::BlockDownloadBlockSizeZero,
        Fault::BlockDownloadWithoutSizeRefused,
        Fault::WriteOnlyEntryRead,
        Fault::LowLimitNotChecked,
        Fault::MappingEntryWrittenWhileEnabled,
        Fault::MappingLengthNotChecked,
        Fault::NotMappableObjectMapped,
        Fault::AbsentObjectMapped,
        Fault::OldMappingSent,
        Fault::ErrorHistoryNotCounted,
        Fault::TimeProducerBitIgnored,
        Fault::TimeConsumerBitIgnored,
        Fault::RestoreCommunicationIgnored,
        Fault::ResetCommunicationResetsApplication,
        Fault::RpdoIgnoredInOperational,
        Fault::NmtForAnyNodeId,
        Fault::ErrorRegisterReadsZero,
        Fault::NoErrorResetEmcy,
        Fault::InhibitedEmcyDropped,
    ];
}

/// The node-ID of every device built here.
pub const NODE_ID: u8 = 5;

/// An UNSIGNED8 with limits 0–100, for the value range aborts.
pub const SET_POINT_INDEX: u16 = 0x2002;
/// A write-only UNSIGNED32, for abort 0x06010001.
pub const WRITE_ONLY_INDEX: u16 = 0x2003;
/// An INTEGER16 with limits -100–100, for the value range aborts below a low limit.
pub const OFFSET_INDEX: u16 = 0x2004;
/// The low limit of [`OFFSET_INDEX`].
pub const OFFSET_LOW: i16 = -100;
/// A DOMAIN of [`DOMAIN_SIZE`] bytes, for segmented and block transfers.
pub const DOMAIN_INDEX: u16 = 0x2000;
/// The DOMAIN's size: several block-upload sub-blocks of 127 segments.
pub const DOMAIN_SIZE: usize = 2000;
/// An ARRAY of 8 UNSIGNED16, mapped into the TPDOs (two entries each).
pub const INPUTS_INDEX: u16 = 0x2100;
/// An ARRAY of 8 UNSIGNED16, mapped into the RPDOs (two entries each).
pub const OUTPUTS_INDEX: u16 = 0x2200;

fn mapping(index: u16, k: u16) -> [u32; 2] {
    let entry = |sub: u16| (u32::from(index) << 16) | (u32::from(sub) << 8) | 16;
    [entry(2 * k + 1), entry(2 * k + 2)]
}

/// The dictionary of the device: the CiA 301 communication objects with their defaults
/// (storage 0x1010/0x1011, error history, heartbeat consumers), four RPDOs and TPDOs, and
/// the application objects above.
pub fn description() -> OdDescription {
    let mut pdos = PdoObjects::new(4, 4);
    for k in 0..4 {
        pdos = pdos
            .rpdo(k, 255, &mapping(OUTPUTS_INDEX, k))
            .tpdo(k, 1, &mapping(INPUTS_INDEX, k));
    }
    let io = |name: &str| {
        SubObject::new(name, DataType::Unsigned16, Access::Rw)
            .mappable()
            .default(Value::Unsigned16(0))
    };
    let options = Cia301Options {
        device_name: "broken CiA 301 device".into(),
        ..Cia301Options::default()
    };
    let b = cia301_defaults(OdBuilder::new(), &options)
        .var(
            DOMAIN_INDEX,
            SubObject::new("Domain", DataType::Domain, Access::Rw)
                .default(Value::Domain(
                    (0..DOMAIN_SIZE).map(|i| (i % 251) as u8).collect(),
                ))
                .max_len(DOMAIN_SIZE),
        )
        .var(
            SET_POINT_INDEX,
            SubObject::new("Set point", DataType::Unsigned8, Access::Rw)
                .limits(Value::Unsigned8(0), Value::Unsigned8(100)),
        )
        .var(
            WRITE_ONLY_INDEX,
            SubObject::new("Command", DataType::Unsigned32, Access::Wo),
        )
        .var(
            OFFSET_INDEX,
            SubObject::new("Offset", DataType::Integer16, Access::Rw)
                .default(Value::Integer16(0))
                .limits(Value::Integer16(OFFSET_LOW), Value::Integer16(100)),
        )
        .array_of(INPUTS_INDEX, "Inputs", 8, io("Input"))
        .array_of(OUTPUTS_INDEX, "Outputs", 8, io("Output"));
    pdos.add_to(b).build().unwrap()
}

/// The device's EDS, generated from its dictionary.
pub fn eds(desc: &OdDescription) -> Eds {
    let mut info = DeviceInfo {
        vendor_name: Some("cantwin".into()),
        product_name: Some("broken CiA 301 device".into()),
        granularity: Some(8),
        nr_of_rx_pdo: Some(4),
        nr_of_tx_pdo: Some(4),
        ..DeviceInfo::default()
    };
    info.set_baud_rates(&[125, 250, 500, 1000]);
    cantwin_eds::from_od(desc, info, FileInfo::new("broken.eds"))
}

/// A node that acknowledges frames and does nothing else: another station on the bus, so
/// that the device's frames are acknowledged (CiA 301 §7.2: an unacknowledged frame is
/// repeated, and the device goes error passive) before the runner attaches.
struct Acknowledger;

impl Node for Acknowledger {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

/// How long the device runs before the runner attaches: its power-up boot-up is over by
/// then, as a real device's is when a tool connects to its bus.
pub const POWERED_BEFORE: Duration = Duration::from_millis(10);

/// A simulation of one bus with the device (broken by `fault`, or not) on it, powered
/// [`POWERED_BEFORE`] ago. The runner's first reset then cannot mistake the power-up
/// boot-up for the answer to it.
pub fn simulation(desc: &Arc<OdDescription>, fault: Option<Fault>) -> (Simulation, BusId, PortId) {
    simulation_powered(desc, fault, POWERED_BEFORE)
}

/// As [`simulation`], with the device powered `powered` ago (`Duration::ZERO`: not yet; the
/// runner then attaches before the device's power-up boot-up).
pub fn simulation_powered(
    desc: &Arc<OdDescription>,
    fault: Option<Fault>,
    powered: Duration,
) -> (Simulation, BusId, PortId) {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R500K));
    let config = DeviceConfig {
        // Every frame reaches the node, as for a controller without acceptance filter: the
        // broken node sees the SDO requests the device itself ignores in STOPPED.
        acceptance_filter: false,
        ..DeviceConfig::new(NODE_ID)
    };
    let device = Device::new(Arc::clone(desc), config).unwrap();
    let port = PortConfig {
        // A whole block-upload sub-block (127 segments) plus the other services' frames.
        queue_depth: 256,
        ..PortConfig::default()
    };
    let port = sim.attach(bus, Broken::new(device, fault), port).unwrap();
    sim.attach(bus, Acknowledger, PortConfig::default())
        .unwrap();
    if powered > Duration::ZERO {
        sim.run_for(powered);
    }
    (sim, bus, port)
}

/// Where a segmented or block transfer of the SDO server stands, as far as the fault needs
/// to know.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Transfer {
    /// No transfer, or an expedited or segmented one (its frames carry a command byte).
    Idle,
    /// A block download: the client's frames are sequence-numbered segments until the
    /// server's end response.
    BlockDownload,
    /// A block upload: once `started` (the client's start request, §7.2.4.3.14) the
    /// server's frames are segments; `last` is the sequence number of the segment with
    /// c = 1 once sent in the current sub-block, `end_next` says that the client
    /// acknowledged it and the server's next frame is the end (§7.2.4.3.15).
    BlockUpload {
        started: bool,
        last: Option<u8>,
        end_next: bool,
    },
}

/// A [`Device`] with one fault.
pub struct Broken {
    device: Device,
    fault: Option<Fault>,
    transfer: Transfer,
    /// The toggle bit the next segment should carry ([`Fault::ToggleIgnored`]).
    toggle: u8,
    /// A reset communication is under way and its boot-up not yet left out.
    reset_communication: bool,
    /// Heartbeats the device produced so far.
    heartbeats: u64,
    /// The block download under way: the segments of the current sub-block taken in
    /// sequence, the data of the sub-blocks the server acknowledged, the sequence number of
    /// the last segment (c = 1) once sent, and whether the client's end request comes next.
    block_segments: Vec<[u8; 7]>,
    block_data: Vec<u8>,
    block_last: Option<u8>,
    block_end_next: bool,
    /// When the next TPDO 1 of [`Fault::TpdoInPreOperational`] is due.
    tpdo_due: Option<Instant>,
    /// A SYNC arrived that [`Fault::CyclicTypeAtEverySync`] or
    /// [`Fault::RtrSyncTypeSentOnSync`] answers with TPDO 1 in place of the device.
    sync_tpdo: bool,
    /// A boot-up went out and no state report since ([`Fault::OperationalReportedAfterBootUp`]).
    booted: bool,
    /// The inhibit time EMCY last seen and the EMCYs sent under it
    /// ([`Fault::InhibitedEmcyDropped`]).
    inhibit_emcys: (u64, u32),
}

/// The most block download data the node keeps to compute a CRC: the DOMAIN and then some
/// (a longer download is aborted by the device anyway).
const MAX_BLOCK_DATA: usize = 2 * DOMAIN_SIZE;

impl Broken {
    /// `device` with `fault` (none: the device as it is).
    pub fn new(device: Device, fault: Option<Fault>) -> Broken {
        Broken {
            device,
            fault,
            transfer: Transfer::Idle,
            toggle: 0,
            reset_communication: false,
            heartbeats: 0,
            block_segments: Vec::new(),
            block_data: Vec::new(),
            block_last: None,
            block_end_next: false,
            tpdo_due: None,
            booted: false,
            sync_tpdo: false,
            inhibit_emcys: (0, 0),
        }
    }

    /// The device.
    pub fn device(&self) -> &Device {
        &self.device
    }

    fn sdo_rx(&self) -> u16 {
        0x600 + u16::from(NODE_ID)
    }

    fn sdo_tx(&self) -> u16 {
        0x580 + u16::from(NODE_ID)
    }

    fn answer(&self, out: &mut Outbox, request: &[u8], abort: Option<u32>) {
        let mut data = [0u8; 8];
        data[1..4].copy_from_slice(&request[1..4]);
        match abort {
            None => data[0] = 0x60,
            Some(code) => {
                data[0] = 0x80;
                data[4..].copy_from_slice(&code.to_le_bytes());
            }
        }
        out.push(Frame::std(self.sdo_tx(), &data).unwrap());
    }

    /// A frame for the device, as the fault lets it through: `None` if the fault answered
    /// it instead.
    fn incoming(&mut self, frame: &Frame, out: &mut Outbox) -> Option<Frame> {
        let id = match frame.id() {
            Id::Standard(id) => id.as_raw(),
            Id::Extended(_) => return Some(*frame),
        };
        let data = frame.data_bytes();
        if self.fault == Some(Fault::ResetIgnoredInStopped)
            && self.device.state() == State::Stopped
            && id == 0x000
            && data.len() == 2
            && (data[0] == 0x81 || data[0] == 0x82)
            && (data[1] == 0 || data[1] == NODE_ID)
        {
            return None;
        }
        if self.fault == Some(Fault::ErrorRegisterReadsZero)
            && id == self.sdo_rx()
            && data.len() == 8
            && data[..4] == [0x40, 0x01, 0x10, 0x00]
        {
            out.push(Frame::std(self.sdo_tx(), &[0x4F, 0x01, 0x10, 0x00, 0, 0, 0, 0]).unwrap());
            return None;
        }
        if self.fault == Some(Fault::NmtForAnyNodeId)
            && id == 0x000
            && data.len() == 2
            && data[1] != 0
            && data[1] != NODE_ID
        {
            return self.incoming(&Frame::std(0, &[data[0], NODE_ID]).unwrap(), out);
        }
        if self.fault == Some(Fault::RpdoIgnoredInOperational)
            && self.device.state() == State::Operational
            && (0..4u16).any(|k| {
                let cob = self
                    .device
                    .od()
                    .get_unsigned(0x1400 + k, 1)
                    .unwrap_or(0x8000_0000);
                cob & 0x8000_0000 == 0 && u64::from(id) == cob & 0x7FF
            })
        {
            return None;
        }
        if let Some(f) = self.outside_operational(id, data, out) {
            return f;
        }
        if let Some(f) = self.transmission_type_fault(id, data, out) {
            return f;
        }
        if id == 0x000 && data.len() == 2 && data[0] == 0x82 && (data[1] == 0 || data[1] == NODE_ID)
        {
            self.reset_communication = true;
            if self.fault == Some(Fault::ResetCommunicationResetsApplication) {
                let _ = self
                    .device
                    .od_mut()
                    .set(SET_POINT_INDEX, 0, &Value::Unsigned8(0));
            }
        }
        if id != self.sdo_rx() || frame.is_remote() || data.len() != 8 {
            return Some(*frame);
        }
        let byte0 = data[0];
        self.track_client(byte0, data);
        match self.fault {
            // Block upload initiate (ccs 5, cs 0): the device gets an ordinary upload
            // initiate of the same object instead, and answers it the ordinary way.
            Some(Fault::BlockUploadSwitchedOnPst0) if byte0 >> 5 == 5 && byte0 & 0x03 == 0 => {
                self.transfer = Transfer::Idle;
                let mut d = [0u8; 8];
                d[0] = 0x40;
                d[1..4].copy_from_slice(&data[1..4]);
                Some(Frame::std(id, &d).unwrap())
            }
            // Block upload initiate: the device is asked for blocks of 127 segments.
            // A valid size only: sizes 0 and 128 are still refused.
            Some(Fault::BlockUploadBlockSizeIgnored)
                if byte0 >> 5 == 5 && byte0 & 0x03 == 0 && (1..=126).contains(&data[4]) =>
            {
                let mut d: [u8; 8] = data.try_into().unwrap();
                d[4] = 127;
                Some(Frame::std(id, &d).unwrap())
            }
            // Block download initiate (ccs 6, cs 0) with s = 0.
            Some(Fault::BlockDownloadWithoutSizeRefused)
                if byte0 >> 5 == 6 && byte0 & 0x01 == 0 && byte0 & 0x02 == 0 =>
            {
                self.transfer = Transfer::Idle;
                self.answer(out, data, Some(0x0607_0010));
                None
            }
            // Upload initiate of the write-only entry: answered with four zero bytes.
            Some(Fault::WriteOnlyEntryRead)
                if byte0 == 0x40 && expedited(data).0 == WRITE_ONLY_INDEX =>
            {
                let mut d = [0u8; 8];
                d[0] = 0x43;
                d[1..4].copy_from_slice(&data[1..4]);
                out.push(Frame::std(self.sdo_tx(), &d).unwrap());
                None
            }
            Some(Fault::LowLimitNotChecked)
                if is_expedited_download(byte0)
                    && expedited(data).0 == OFFSET_INDEX
                    && i16::from_le_bytes([data[4], data[5]]) < OFFSET_LOW =>
            {
                self.answer(out, data, None);
                None
            }
            Some(
                fault @ (Fault::MappingEntryWrittenWhileEnabled
                | Fault::MappingLengthNotChecked
                | Fault::NotMappableObjectMapped
                | Fault::AbsentObjectMapped),
            ) if is_expedited_download(byte0) => self.mapping_fault(fault, frame, out),
            Some(Fault::ErrorHistoryNotCounted)
                if byte0 == 0x40 && (expedited(data).0, expedited(data).1) == (0x1003, 0) =>
            {
                // Expedited, one byte (n = 3): 0.
                let mut d = [0u8; 8];
                d[0] = 0x4F;
                d[1..4].copy_from_slice(&data[1..4]);
                out.push(Frame::std(self.sdo_tx(), &d).unwrap());
                None
            }
            Some(fault @ (Fault::TimeProducerBitIgnored | Fault::TimeConsumerBitIgnored))
                if is_expedited_download(byte0)
                    && (expedited(data).0, expedited(data).1) == (0x1012, 0) =>
            {
                let bit = if fault == Fault::TimeProducerBitIgnored {
                    0x4000_0000
                } else {
                    0x8000_0000
                };
                let now = self.device.od().get_unsigned(0x1012, 0).unwrap_or(0) as u32;
                let new = u32::from_le_bytes(expedited(data).2);
                if new & bit != 0 && now & bit == 0 {
                    self.answer(out, data, None);
                    return None;
                }
                Some(*frame)
            }
            Some(Fault::RestoreCommunicationIgnored)
                if is_expedited_download(byte0)
                    && (expedited(data).0, expedited(data).1) == (0x1011, 2)
                    && expedited(data).2 == *b"load" =>
            {
                self.answer(out, data, None);
                None
            }
            Some(Fault::SdoInStopped) if self.device.state() == State::Stopped => {
                // 0x08000022: data cannot be transferred because of the present device state.
                self.answer(out, data, Some(0x0800_0022));
                None
            }
            Some(fault @ (Fault::ToggleIgnored | Fault::UploadToggleIgnored))
                if self.transfer == Transfer::Idle =>
            {
                let mut d: [u8; 8] = data.try_into().unwrap();
                match byte0 >> 5 {
                    // Initiate download or upload: the first segment carries toggle 0.
                    1 | 2 => self.toggle = 0,
                    // Download segment ([`Fault::ToggleIgnored`] only).
                    0 if fault == Fault::ToggleIgnored => {
                        d[0] = (byte0 & !0x10) | (self.toggle << 4);
                        self.toggle ^= 1;
                    }
                    // Upload segment request.
                    3 => {
                        d[0] = (byte0 & !0x10) | (self.toggle << 4);
                        self.toggle ^= 1;
                    }
                    _ => {}
                }
                Some(Frame::std(id, &d).unwrap())
            }
            Some(Fault::MappingChangeOnValidPdo) if is_expedited_download(byte0) => {
                let (index, sub, value) = expedited(data);
                let mapping =
                    (0x1600..=0x17FF).contains(&index) || (0x1A00..=0x1BFF).contains(&index);
                let comm = index - 0x200;
                let cob = self
                    .device
                    .od()
                    .get_unsigned(comm, 1)
                    .unwrap_or(0x8000_0000) as u32;
                if !mapping || cob & 0x8000_0000 != 0 {
                    return Some(*frame);
                }
                let abort = self.change_mapping(comm, index, sub, value, cob).err();
                self.answer(out, data, abort);
                None
            }
            Some(Fault::EmcyCobIdChangeWhileValid) if is_expedited_download(byte0) => {
                let (index, sub, value) = expedited(data);
                let cob = self
                    .device
                    .od()
                    .get_unsigned(0x1014, 0)
                    .unwrap_or(0x8000_0000) as u32;
                let new = u32::from_le_bytes(value);
                if (index, sub) != (0x1014, 0)
                    || cob & 0x8000_0000 != 0
                    || new & 0x1FFF_FFFF == cob & 0x1FFF_FFFF
                {
                    return Some(*frame);
                }
                // Made invalid first, as a client would have to, then the new value.
                let abort = self
                    .device
                    .write(0x1014, 0, &(cob | 0x8000_0000).to_le_bytes())
                    .and_then(|()| self.device.write(0x1014, 0, &new.to_le_bytes()))
                    .err()
                    .map(|a| a.to_u32());
                self.answer(out, data, abort);
                None
            }
            Some(Fault::PdoCobIdChangeWhileValid) if is_expedited_download(byte0) => {
                let (index, sub, value) = expedited(data);
                let comm = (0x1400..=0x15FF).contains(&index) || (0x1800..=0x19FF).contains(&index);
                let cob = self
                    .device
                    .od()
                    .get_unsigned(index, 1)
                    .unwrap_or(0x8000_0000) as u32;
                let new = u32::from_le_bytes(value);
                if !comm
                    || sub != 1
                    || cob & 0x8000_0000 != 0
                    || new & 0x8000_0000 != 0
                    || new & 0x1FFF_FFFF == cob & 0x1FFF_FFFF
                {
                    return Some(*frame);
                }
                let abort = self
                    .device
                    .write(index, 1, &(cob | 0x8000_0000).to_le_bytes())
                    .and_then(|()| self.device.write(index, 1, &new.to_le_bytes()))
                    .err()
                    .map(|a| a.to_u32());
                self.answer(out, data, abort);
                None
            }
            Some(Fault::PdoCobIdChangeWhileValidUnanswered) if is_expedited_download(byte0) => {
                let (index, sub, value) = expedited(data);
                let comm = (0x1400..=0x15FF).contains(&index) || (0x1800..=0x19FF).contains(&index);
                let cob = self
                    .device
                    .od()
                    .get_unsigned(index, 1)
                    .unwrap_or(0x8000_0000) as u32;
                let new = u32::from_le_bytes(value);
                if !comm
                    || sub != 1
                    || cob & 0x8000_0000 != 0
                    || new & 0x8000_0000 != 0
                    || new & 0x1FFF_FFFF == cob & 0x1FFF_FFFF
                {
                    return Some(*frame);
                }
                // Swallowed: the client hears nothing and the COB-ID keeps its value.
                None
            }
            Some(Fault::ErrorHistoryWriteAccepted) if is_expedited_download(byte0) => {
                let (index, sub, value) = expedited(data);
                if (index, sub) != (0x1003, 0) || value[0] == 0 {
                    return Some(*frame);
                }
                self.answer(out, data, None);
                None
            }
            Some(Fault::BlockDownloadCrcNotChecked)
                if self.transfer == Transfer::BlockDownload
                    && self.block_end_next
                    && byte0 & 0xE3 == 0xC1 =>
            {
                // The end request (ccs 6, cs 1): n bytes of the last segment carry no data.
                let n = usize::from((byte0 >> 2) & 0x07);
                let len = self.block_data.len().saturating_sub(n);
                let crc = Crc16::of(&self.block_data[..len]).to_le_bytes();
                let mut d: [u8; 8] = data.try_into().unwrap();
                d[1..3].copy_from_slice(&crc);
                Some(Frame::std(id, &d).unwrap())
            }
            Some(Fault::DuplicateHeartbeatConsumerAccepted) if is_expedited_download(byte0) => {
                let (index, sub, value) = expedited(data);
                let v = u32::from_le_bytes(value);
                let node = (v >> 16) & 0xFF;
                let od = self.device.od();
                let entries = od.get_unsigned(0x1016, 0).unwrap_or(0) as u8;
                let duplicate = (1..=entries).filter(|&j| j != sub).any(|j| {
                    let other = od.get_unsigned(0x1016, j).unwrap_or(0) as u32;
                    other & 0xFFFF != 0 && (other >> 16) & 0xFF == node
                });
                if index != 0x1016 || sub == 0 || v & 0xFFFF == 0 || !duplicate {
                    return Some(*frame);
                }
                // Stored as it is, past the check the device would make.
                let abort = self
                    .device
                    .od_mut()
                    .set(0x1016, sub, &Value::Unsigned32(v))
                    .err()
                    .map(|a| a.to_u32());
                self.answer(out, data, abort);
                None
            }
            Some(Fault::StoreWithoutSignature) if is_expedited_download(byte0) => {
                let (index, sub, _) = expedited(data);
                if index != 0x1010 || sub == 0 {
                    return Some(*frame);
                }
                let mut d: [u8; 8] = data.try_into().unwrap();
                // Four bytes, size indicated: the signature "save" (0x65766173).
                d[0] = 0x23;
                d[4..].copy_from_slice(b"save");
                Some(Frame::std(id, &d).unwrap())
            }
            _ => Some(*frame),
        }
    }

    /// The mapping faults of an invalid PDO: `None` when the fault answered the request.
    fn mapping_fault(&mut self, fault: Fault, frame: &Frame, out: &mut Outbox) -> Option<Frame> {
        let data = frame.data_bytes();
        let (index, sub, value) = expedited(data);
        let mapping = (0x1600..=0x17FF).contains(&index) || (0x1A00..=0x1BFF).contains(&index);
        let comm = index.wrapping_sub(0x200);
        let od = self.device.od();
        let cob = od.get_unsigned(comm, 1).unwrap_or(0) as u32;
        if !mapping || cob & 0x8000_0000 == 0 {
            return Some(*frame);
        }
        let count = od.get_unsigned(index, 0).unwrap_or(0) as u8;
        let entry = u32::from_le_bytes(value);
        let target = (entry >> 16) as u16;
        let target_sub = (entry >> 8) as u8;
        let exists = od.description().locate(target, target_sub).is_ok();
        let mappable = exists
            && od
                .description()
                .locate(target, target_sub)
                .is_ok_and(|id| od.description().sub_object(id).pdo_mappable);
        let answered = match fault {
            Fault::MappingEntryWrittenWhileEnabled if sub != 0 && count != 0 => {
                let d = &mut self.device;
                let r = d
                    .write(index, 0, &[0])
                    .and_then(|()| d.write(index, sub, &value))
                    .and_then(|()| d.write(index, 0, &[count]));
                Some(r.err().map(|a| a.to_u32()))
            }
            Fault::MappingLengthNotChecked if sub == 0 => {
                let bits: Option<u32> = (1..=value[0])
                    .map(|s| od.get_unsigned(index, s).map(|e| (e & 0xFF) as u32))
                    .sum();
                bits.is_some_and(|b| b > 64).then_some(None)
            }
            Fault::NotMappableObjectMapped if sub != 0 && count == 0 => {
                (exists && !mappable).then_some(None)
            }
            Fault::AbsentObjectMapped if sub != 0 && count == 0 => {
                (entry != 0 && target >= 0x20 && !exists).then_some(None)
            }
            _ => None,
        };
        match answered {
            Some(abort) => {
                self.answer(out, data, abort);
                None
            }
            None => Some(*frame),
        }
    }

    /// The mapping change the standard forbids on a valid PDO, done the allowed way behind
    /// the client's back: PDO invalid, mapping disabled, entry written, mapping and PDO
    /// restored.
    fn change_mapping(
        &mut self,
        comm: u16,
        index: u16,
        sub: u8,
        value: [u8; 4],
        cob: u32,
    ) -> Result<(), u32> {
        let d = &mut self.device;
        let count = d.od().get_unsigned(index, 0).unwrap_or(0) as u8;
        let r = d
            .write(comm, 1, &(cob | 0x8000_0000).to_le_bytes())
            .and_then(|()| {
                if sub == 0 {
                    d.write(index, 0, &value[..1])
                } else {
                    d.write(index, 0, &[0])
                        .and_then(|()| d.write(index, sub, &value))
                        .and_then(|()| d.write(index, 0, &[count]))
                }
            });
        let restored = d.write(comm, 1, &cob.to_le_bytes());
        r.and(restored).map_err(|a| a.to_u32())
    }

    /// Follows block transfers from the client's frames.
    fn track_client(&mut self, byte0: u8, data: &[u8]) {
        match self.transfer {
            Transfer::Idle => match byte0 >> 5 {
                // Block download initiate (ccs 6, cs 0).
                6 if byte0 & 0x01 == 0 => {
                    self.transfer = Transfer::BlockDownload;
                    self.block_segments.clear();
                    self.block_data.clear();
                    self.block_last = None;
                    self.block_end_next = false;
                }
                // Block upload initiate (ccs 5, cs 0).
                5 if byte0 & 0x03 == 0 => {
                    self.transfer = Transfer::BlockUpload {
                        started: false,
                        last: None,
                        end_next: false,
                    }
                }
                _ => {}
            },
            // Segments carry no command specifier; only an abort ends the transfer early. A
            // segment is taken when it is the next in sequence (§7.2.4.3.10).
            Transfer::BlockDownload if !self.block_end_next && byte0 != 0x80 => {
                let seq = byte0 & 0x7F;
                if usize::from(seq) == self.block_segments.len() + 1 {
                    self.block_segments.push(data[1..8].try_into().unwrap());
                    if byte0 & 0x80 != 0 {
                        self.block_last = Some(seq);
                    }
                }
            }
            Transfer::BlockDownload => {}
            Transfer::BlockUpload { last, .. } => match byte0 {
                // Start upload (ccs 5, cs 3).
                0xA3 => {
                    self.transfer = Transfer::BlockUpload {
                        started: true,
                        last: None,
                        end_next: false,
                    }
                }
                // Block acknowledgement (ccs 5, cs 2) of the sequence number in byte 1: the
                // end comes next if it covers the last segment, else the server goes on
                // after the acknowledged one and sends the last segment again.
                0xA2 => {
                    let end_next = last.is_some() && last == Some(data[1]);
                    self.transfer = Transfer::BlockUpload {
                        started: true,
                        last: if end_next { last } else { None },
                        end_next,
                    }
                }
                // The client's end response (ccs 5, cs 1).
                0xA1 => self.transfer = Transfer::Idle,
                _ => {}
            },
        }
        if byte0 == 0x80 {
            self.transfer = Transfer::Idle;
        }
    }

    /// A frame from the device, as the fault lets it out: `None` if it is left out.
    fn outgoing(&mut self, frame: Frame) -> Option<Frame> {
        let Id::Standard(raw) = frame.id() else {
            return Some(frame);
        };
        let id = raw.as_raw();
        let data = frame.data_bytes();
        if id == 0x700 + u16::from(NODE_ID) && data.len() == 1 {
            if data[0] == 0 {
                self.booted = true;
                let after_reset = std::mem::take(&mut self.reset_communication);
                if after_reset && self.fault == Some(Fault::NoBootUpAfterResetCommunication) {
                    return None;
                }
            } else {
                if std::mem::take(&mut self.booted)
                    && self.fault == Some(Fault::OperationalReportedAfterBootUp)
                {
                    return Some(Frame::std(id, &[(data[0] & 0x80) | 0x05]).unwrap());
                }
                self.heartbeats += 1;
                if self.fault == Some(Fault::HeartbeatAtTwiceThePeriod) && self.heartbeats % 2 == 0
                {
                    return None;
                }
            }
            return Some(frame);
        }
        if self.fault == Some(Fault::InhibitedEmcyDropped)
            && id == 0x080 + u16::from(NODE_ID)
            && data.len() == 8
        {
            let inhibit = self.device.od().get_unsigned(0x1015, 0).unwrap_or(0);
            if inhibit != self.inhibit_emcys.0 {
                self.inhibit_emcys = (inhibit, 0);
            }
            self.inhibit_emcys.1 += 1;
            if inhibit != 0 && self.inhibit_emcys.1 > 1 {
                return None;
            }
        }
        if self.fault == Some(Fault::NoErrorResetEmcy)
            && id == 0x080 + u16::from(NODE_ID)
            && data.len() == 8
            && data[..2] == [0, 0]
        {
            return None;
        }
        if self.fault == Some(Fault::OldMappingSent)
            && !frame.is_remote()
            && data.len() != 4
            && let Some(old) = self.tpdo1_frame()
            && old.id() == frame.id()
        {
            return Some(old);
        }
        if self.fault == Some(Fault::AcyclicTpdoNeverSent) && !frame.is_remote() {
            let od = self.device.od();
            let acyclic = (0..4u16).any(|k| {
                let cob = od.get_unsigned(0x1800 + k, 1).unwrap_or(0x8000_0000) as u32;
                cob & 0x8000_0000 == 0
                    && cob & 0x7FF == u32::from(id)
                    && od.get_unsigned(0x1800 + k, 2).unwrap_or(255) == 0
            });
            if acyclic {
                return None;
            }
        }
        if id != self.sdo_tx() || data.len() != 8 {
            return Some(frame);
        }
        let byte0 = data[0];
        if self.fault == Some(Fault::BlockDownloadBlockSizeZero)
            && self.transfer == Transfer::BlockDownload
            && byte0 & 0xE3 == 0xA0
        {
            // The initiate answer (scs 5, ss 0): block size 0.
            let mut d: [u8; 8] = data.try_into().unwrap();
            d[4] = 0;
            return Some(Frame::std(id, &d).unwrap());
        }
        match self.transfer {
            Transfer::BlockDownload if byte0 == 0xA1 || byte0 == 0x80 => {
                self.transfer = Transfer::Idle;
            }
            // Block acknowledgement (scs 5, ss 2) of the sequence number in byte 1.
            Transfer::BlockDownload if byte0 == 0xA2 => {
                let acked = usize::from(data[1]).min(self.block_segments.len());
                if self.block_data.len() + 7 * acked <= MAX_BLOCK_DATA {
                    for seg in &self.block_segments[..acked] {
                        self.block_data.extend_from_slice(seg);
                    }
                }
                self.block_end_next = self
                    .block_last
                    .is_some_and(|last| usize::from(last) <= acked);
                self.block_segments.clear();
                self.block_last = None;
            }
            Transfer::BlockUpload { end_next: true, .. } => {
                self.transfer = Transfer::Idle;
                if self.fault == Some(Fault::WrongBlockUploadCrc) && byte0 & 0xE3 == 0xC1 {
                    let mut d: [u8; 8] = data.try_into().unwrap();
                    d[1] ^= 0xFF;
                    d[2] ^= 0x5A;
                    return Some(Frame::std(id, &d).unwrap());
                }
            }
            Transfer::BlockUpload {
                end_next: false, ..
            } if byte0 == 0x80 => {
                self.transfer = Transfer::Idle;
            }
            Transfer::BlockUpload {
                started: true,
                last: None,
                end_next: false,
            } if byte0 & 0x80 != 0 => {
                // The segment with c = 1.
                self.transfer = Transfer::BlockUpload {
                    started: true,
                    last: Some(byte0 & 0x7F),
                    end_next: false,
                };
            }
            _ => {}
        }
        Some(frame)
    }

    /// The PDO faults outside OPERATIONAL: `Some(None)` when the fault took the frame.
    fn outside_operational(
        &mut self,
        id: u16,
        data: &[u8],
        out: &mut Outbox,
    ) -> Option<Option<Frame>> {
        let state = self.device.state();
        let od = self.device.od();
        let rpdo1 = od.get_unsigned(0x1400, 1).unwrap_or(0x8000_0000) as u32;
        let is_rpdo1 = rpdo1 & 0x8000_0000 == 0 && u32::from(id) == rpdo1 & 0x7FF;
        match self.fault {
            Some(Fault::RpdoProcessedInStopped) if state == State::Stopped => {}
            Some(Fault::RpdoProcessedInPreOperational) if state == State::PreOperational => {}
            Some(Fault::EmcyInStopped)
                if state == State::Stopped && is_rpdo1 && data.len() != 4 =>
            {
                let reg = self.device.error_register() | 0x10;
                out.push(
                    Frame::std(0x80 + u16::from(NODE_ID), &[0x10, 0x82, reg, 0, 0, 0, 0, 0])
                        .unwrap(),
                );
                return Some(None);
            }
            Some(Fault::SyncTpdoInStopped) if state == State::Stopped && id == 0x080 => {
                let cob = od.get_unsigned(0x1800, 1).unwrap_or(0x8000_0000) as u32;
                let ty = od.get_unsigned(0x1800, 2).unwrap_or(255);
                if cob & 0x8000_0000 == 0 && (1..=240).contains(&ty) {
                    let a = od.get_unsigned(INPUTS_INDEX, 1).unwrap_or(0) as u16;
                    let b = od.get_unsigned(INPUTS_INDEX, 2).unwrap_or(0) as u16;
                    let [a0, a1] = a.to_le_bytes();
                    let [b0, b1] = b.to_le_bytes();
                    out.push(Frame::std((cob & 0x7FF) as u16, &[a0, a1, b0, b1]).unwrap());
                }
                return None;
            }
            _ => return None,
        }
        if !is_rpdo1 || data.len() != 4 {
            return None;
        }
        // RPDO 1 maps 0x2200 sub 1 and 2, 16 bits each.
        for (sub, v) in [(1u8, [data[0], data[1]]), (2, [data[2], data[3]])] {
            let _ = self.device.set_value(
                OUTPUTS_INDEX,
                sub,
                &Value::Unsigned16(u16::from_le_bytes(v)),
            );
        }
        Some(None)
    }

    /// TPDO 1 with the current values of its mapping (0x2100 sub 1 and 2), if valid.
    fn tpdo1_frame(&self) -> Option<Frame> {
        let od = self.device.od();
        let cob = od.get_unsigned(0x1800, 1)? as u32;
        if cob & 0x8000_0000 != 0 {
            return None;
        }
        let a = od.get_unsigned(INPUTS_INDEX, 1)? as u16;
        let b = od.get_unsigned(INPUTS_INDEX, 2)? as u16;
        let [a0, a1] = a.to_le_bytes();
        let [b0, b1] = b.to_le_bytes();
        Frame::std((cob & 0x7FF) as u16, &[a0, a1, b0, b1]).ok()
    }

    /// The transmission type faults: `Some(None)` when the fault took the frame.
    fn transmission_type_fault(
        &mut self,
        id: u16,
        data: &[u8],
        out: &mut Outbox,
    ) -> Option<Option<Frame>> {
        let ty = self.device.od().get_unsigned(0x1800, 2).unwrap_or(255);
        let operational = self.device.state() == State::Operational;
        let on_sync = match self.fault {
            Some(Fault::CyclicTypeAtEverySync) => (3..=240).contains(&ty),
            Some(Fault::RtrSyncTypeSentOnSync) => ty == 252,
            Some(Fault::ReservedTransmissionTypeAccepted)
                if id == self.sdo_rx()
                    && data.len() == 8
                    && is_expedited_download(data[0])
                    && expedited(data).0 == 0x1800
                    && expedited(data).1 == 2
                    && (241..=251).contains(&data[4]) =>
            {
                self.answer(out, data, None);
                return Some(None);
            }
            _ => false,
        };
        if on_sync && operational && id == 0x080 {
            self.sync_tpdo = true;
        }
        None
    }

    /// TPDO 1 as the device would send it in OPERATIONAL: its COB-ID, if valid, and its
    /// mapping (0x2100 sub 1 and 2, 16 bits each); with its event timer.
    fn tpdo1(&self) -> Option<(Frame, Duration)> {
        let od = self.device.od();
        let cob = od.get_unsigned(0x1800, 1)? as u32;
        let timer = od.get_unsigned(0x1800, 5)?;
        if cob & 0x8000_0000 != 0 || timer == 0 {
            return None;
        }
        let a = od.get_unsigned(INPUTS_INDEX, 1)? as u16;
        let b = od.get_unsigned(INPUTS_INDEX, 2)? as u16;
        let [a0, a1] = a.to_le_bytes();
        let [b0, b1] = b.to_le_bytes();
        let frame = Frame::std((cob & 0x7FF) as u16, &[a0, a1, b0, b1]).ok()?;
        Some((frame, Duration::from_millis(timer)))
    }

    /// Sends TPDO 1 when due in PRE-OPERATIONAL ([`Fault::TpdoInPreOperational`]) and
    /// schedules the next one.
    fn tpdo_outside_operational(&mut self, now: Instant, out: &mut Outbox) {
        let wanted = self.fault == Some(Fault::TpdoInPreOperational)
            && self.device.state() == State::PreOperational;
        let Some((frame, period)) = self.tpdo1().filter(|_| wanted) else {
            self.tpdo_due = None;
            return;
        };
        match self.tpdo_due {
            Some(due) if due <= now => {
                out.push(frame);
                self.tpdo_due = Some(now + period);
            }
            Some(_) => {}
            None => self.tpdo_due = Some(now + period),
        }
    }

    fn flush(&mut self, produced: &mut Outbox, out: &mut Outbox) {
        let frames: Vec<Frame> = produced.drain().collect();
        for f in frames {
            if let Some(f) = self.outgoing(f) {
                out.push(f);
            }
        }
    }
}

fn is_expedited_download(byte0: u8) -> bool {
    // ccs 1 (initiate download), e = 1.
    byte0 >> 5 == 1 && byte0 & 0x02 != 0
}

/// Index, sub-index and the four data bytes of an initiate request.
fn expedited(data: &[u8]) -> (u16, u8, [u8; 4]) {
    (
        u16::from_le_bytes([data[1], data[2]]),
        data[3],
        [data[4], data[5], data[6], data[7]],
    )
}

impl Node for Broken {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.transfer = Transfer::Idle;
        self.reset_communication = false;
        let mut produced = Outbox::new();
        self.device.on_power_up(now, &mut produced);
        self.flush(&mut produced, out);
    }

    fn on_frame(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let mut produced = Outbox::new();
        if let Some(f) = self.incoming(frame, &mut produced) {
            self.device.on_frame(&f, now, &mut produced);
        }
        if std::mem::take(&mut self.sync_tpdo)
            && let Some(tpdo) = self.tpdo1_frame()
        {
            // The device's own answer to the SYNC (none, or its every-n-th TPDO 1) is
            // replaced by TPDO 1 at this SYNC.
            let rest: Vec<Frame> = produced.drain().filter(|f| f.id() != tpdo.id()).collect();
            for f in rest {
                produced.push(f);
            }
            produced.push(tpdo);
        }
        self.flush(&mut produced, out);
        self.tpdo_outside_operational(now, out);
    }

    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        let mut produced = Outbox::new();
        self.device.on_tick(now, &mut produced);
        self.flush(&mut produced, out);
        self.tpdo_outside_operational(now, out);
    }

    fn next_deadline(&self) -> Option<Instant> {
        match (self.device.next_deadline(), self.tpdo_due) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn on_sent(&mut self, frame: &Frame, now: Instant, out: &mut Outbox) {
        let mut produced = Outbox::new();
        self.device.on_sent(frame, now, &mut produced);
        self.flush(&mut produced, out);
    }

    fn on_controller_event(&mut self, event: ControllerEvent, now: Instant, out: &mut Outbox) {
        let mut produced = Outbox::new();
        self.device.on_controller_event(event, now, &mut produced);
        self.flush(&mut produced, out);
    }
}
