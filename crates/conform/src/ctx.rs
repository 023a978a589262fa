//! What a case works with: the transport, wrapped so that every frame sent and seen is
//! logged for the report, with SDO transfers through [`SdoClient`], raw SDO exchanges for
//! the malformed requests a client never sends, and NMT commands.

use cantwin_can::{Duration, Frame, Id, Instant, Outbox};
use cantwin_canopen::AbortCode;
use cantwin_canopen::master::{Mode, SdoClient, SdoEvent};
use cantwin_canopen::wire::NmtCs;
use cantwin_eds::Eds;

use crate::Options;
use crate::profile::{FailureKind, Profile};
use crate::report::{Direction, LoggedFrame, MAX_LOGGED_FRAMES};
use crate::transport::{Transport, TransportError};

/// Why a case did not pass.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Finding {
    /// The device is wrong; `abort` is the code it answered with, if that was the fault;
    /// `kind` what kind of failure it is (what a deviation may excuse).
    Fail {
        why: String,
        abort: Option<AbortCode>,
        kind: FailureKind,
    },
    /// The optional feature is not offered; `abort` is the code the device refused it
    /// with, if it did.
    NotSupported {
        why: String,
        abort: Option<AbortCode>,
    },
    /// Nothing to check on this device.
    NotApplicable(String),
    /// The transport failed: the run ends.
    Transport(TransportError),
}

impl From<TransportError> for Finding {
    fn from(e: TransportError) -> Self {
        Finding::Transport(e)
    }
}

/// A failure with this reason: a wrong answer or content ([`FailureKind::Value`]).
pub(crate) fn fail(why: impl Into<String>) -> Finding {
    fail_kind(FailureKind::Value, why)
}

/// A failure of `kind` with this reason (not an abort: [`fail_abort`] has the code).
pub(crate) fn fail_kind(kind: FailureKind, why: impl Into<String>) -> Finding {
    Finding::Fail {
        why: why.into(),
        abort: None,
        kind,
    }
}

/// A failure because the device answered with abort `code`.
pub(crate) fn fail_abort(why: impl Into<String>, code: AbortCode) -> Finding {
    Finding::Fail {
        why: format!("{}: abort 0x{:08X}", why.into(), code.to_u32()),
        abort: Some(code),
        kind: FailureKind::Abort,
    }
}

/// A failure of an SDO transfer `a`: the server's abort, or silence when the client gave
/// up (a timeout, or an answer it could not take).
pub(crate) fn fail_sdo(why: impl Into<String>, a: Aborted) -> Finding {
    Finding::Fail {
        why: format!("{}: {a}", why.into()),
        abort: a.by_server.then_some(a.code),
        kind: if a.by_server {
            FailureKind::Abort
        } else {
            FailureKind::Silence
        },
    }
}

/// The optional feature is not offered.
pub(crate) fn not_supported(why: impl Into<String>) -> Finding {
    Finding::NotSupported {
        why: why.into(),
        abort: None,
    }
}

/// What a case returns: a note on success, or why not.
pub(crate) type Outcome = Result<String, Finding>;

/// An SDO transfer that did not complete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Aborted {
    pub code: AbortCode,
    /// The server sent the abort (else the client gave up: a timeout or a protocol error).
    pub by_server: bool,
}

impl std::fmt::Display for Aborted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let who = if self.by_server { "server" } else { "client" };
        write!(f, "abort 0x{:08X} ({who})", self.code.to_u32())
    }
}

/// Every entry of the file with what reading it gave, in file order.
pub(crate) type Scan = Vec<(u16, u8, Result<Vec<u8>, Aborted>)>;

/// The case context.
pub(crate) struct Ctx<'a> {
    t: &'a mut dyn Transport,
    pub node: u8,
    pub eds: &'a Eds,
    pub profile: &'a Profile,
    pub options: &'a Options,
    start: Instant,
    log: Vec<LoggedFrame>,
    omitted: u64,
    /// Every entry of the file as first read by the EDS area (read once: a real device
    /// answers hundreds of uploads slowly).
    pub scan: Option<Scan>,
    /// The node-IDs other nodes have shown on the bus (bit n: node-ID n), so that a case
    /// that needs a node-ID nobody uses (a heartbeat to consume, an NMT command for another
    /// node) does not pick one that is alive.
    seen: u128,
    /// The identifiers of the frames of at most one byte (a SYNC's length, CiA 301
    /// §7.2.5.3) seen before the first case.
    short_before_cases: std::collections::BTreeSet<u32>,
    /// The first case has begun: `short_before_cases` is complete.
    cases_begun: bool,
    /// SYNC frames came from another producer before the first case: the cases whose
    /// verdict depends on SYNC timing cannot be judged.
    pub foreign_sync: bool,
    /// The PDOs whose mapping in the file cannot run on any device made from it (an
    /// entry names an object the file lacks, is not mappable, or the whole is too long,
    /// CiA 301 §7.5.2.36, §7.5.2.38), by communication index, with why: the PDO cases
    /// leave them out, since the device must refuse the file's own mapping for them.
    pub unrunnable: std::collections::BTreeMap<u16, String>,
}

/// The PDOs of `eds` whose file mapping cannot run, by communication index, from the
/// warnings of [`cantwin_eds::pdo_issues`] on the file as the device comes up with it
/// (a DCF's `ParameterValue`s as defaults).
fn unrunnable_pdos(eds: &Eds) -> std::collections::BTreeMap<u16, String> {
    let mut out = std::collections::BTreeMap::new();
    for issue in cantwin_eds::pdo_issues(&cantwin_eds::configured(eds)) {
        // The section names the mapping object: `1A00` or `1A00sub1`.
        let Some(map) = issue
            .section
            .get(..4)
            .and_then(|h| u16::from_str_radix(h, 16).ok())
        else {
            continue;
        };
        if matches!(map, 0x1600..=0x17FF | 0x1A00..=0x1BFF) {
            out.entry(map - 0x200).or_insert(issue.message);
        }
    }
    out
}

/// The node-ID a frame of the pre-defined connection set shows (CiA 301 §7.3.5): EMCY
/// (0x081..0x0FF), the default PDOs (0x181..0x57F), SDO responses (0x581..0x5FF) and
/// error control (0x701..0x77F).
fn node_of(id: Id) -> Option<u8> {
    let Id::Standard(_) = id else { return None };
    let raw = id.as_raw();
    let n = (raw & 0x7F) as u8;
    let base = raw & !0x7F;
    let known = matches!(base, 0x080 | 0x580 | 0x700) || (0x180..=0x500).contains(&base);
    (known && n != 0).then_some(n)
}

fn id16(base: u16, node: u8) -> Id {
    Id::standard(base + u16::from(node)).unwrap_or(Id::Standard(cantwin_can::StandardId::MAX))
}

impl<'a> Ctx<'a> {
    pub fn new(
        t: &'a mut dyn Transport,
        node: u8,
        eds: &'a Eds,
        profile: &'a Profile,
        options: &'a Options,
    ) -> Self {
        let start = t.now();
        Ctx {
            t,
            node,
            eds,
            profile,
            options,
            start,
            log: Vec::new(),
            omitted: 0,
            scan: None,
            seen: 0,
            short_before_cases: std::collections::BTreeSet::new(),
            cases_begun: false,
            foreign_sync: false,
            unrunnable: unrunnable_pdos(eds),
        }
    }

    pub fn describe(&self) -> String {
        self.t.describe()
    }

    pub fn now(&self) -> Instant {
        self.t.now()
    }

    /// Microseconds since the run started.
    pub fn rel_us(&self, t: Instant) -> u64 {
        t.saturating_duration_since(self.start).as_micros()
    }

    /// The log of the case that just ended.
    pub fn take_log(&mut self) -> (Vec<LoggedFrame>, u64) {
        (
            std::mem::take(&mut self.log),
            std::mem::replace(&mut self.omitted, 0),
        )
    }

    fn record(&mut self, t: Instant, dir: Direction, frame: &Frame) {
        if dir == Direction::Response
            && let Some(n) = node_of(frame.id())
        {
            self.seen |= 1u128 << n;
        }
        if dir == Direction::Response
            && !self.cases_begun
            && !frame.is_remote()
            && frame.len() <= 1
            && let Id::Standard(_) = frame.id()
        {
            self.short_before_cases.insert(frame.id().as_raw());
        }
        if self.log.len() >= MAX_LOGGED_FRAMES {
            self.omitted += 1;
        } else {
            let t_us = self.rel_us(t);
            self.log.push(LoggedFrame {
                t_us,
                dir,
                frame: frame.to_string(),
            });
        }
    }

    /// A node-ID in 1..=127 that is neither the device's nor seen on the bus so far, the
    /// first after the device's (CiA 301 §7.3.4: every node on a network has its own).
    pub fn free_node(&self) -> u8 {
        (1..=127u8)
            .map(|k| ((u16::from(self.node) - 1 + u16::from(k)) % 127 + 1) as u8)
            .find(|&n| n != self.node && self.seen & (1u128 << n) == 0)
            .unwrap_or(if self.node >= 127 { 1 } else { self.node + 1 })
    }

    /// Ends the time before the first case: whether SYNC frames came meanwhile from a
    /// producer other than the device, on 0x080 or the device's COB-ID SYNC (0x1005,
    /// CiA 301 §7.5.2.5). The device is the producer only with bit 30 of 0x1005 set; a
    /// network has a single producer (§7.2.5).
    pub fn begin_cases(&mut self) -> Result<(), Finding> {
        let cob = if self.eds.objects.contains_key(&0x1005) {
            match self.upload(0x1005, 0)? {
                Ok(d) if !d.is_empty() && d.len() <= 4 => {
                    let mut b = [0u8; 4];
                    b[..d.len()].copy_from_slice(&d);
                    Some(u32::from_le_bytes(b))
                }
                _ => None,
            }
        } else {
            None
        };
        self.cases_begun = true;
        let own = cob.is_some_and(|c| c & 0x4000_0000 != 0);
        let id = cob.map_or(0x080, |c| c & 0x7FF);
        self.foreign_sync = !own
            && (self.short_before_cases.contains(&0x080) || self.short_before_cases.contains(&id));
        Ok(())
    }

    /// Sends `frame`, logged as stimulus.
    pub fn send(&mut self, frame: Frame) -> Result<(), Finding> {
        let now = self.t.now();
        self.record(now, Direction::Stimulus, &frame);
        self.t.send(frame)?;
        Ok(())
    }

    /// The next frame until `deadline`, logged as response.
    pub fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, Finding> {
        let got = self.t.recv(deadline)?;
        if let Some((t, f)) = &got {
            self.record(*t, Direction::Response, f);
        }
        Ok(got)
    }

    /// The first frame within `within` that `pred` accepts (others are logged and passed).
    pub fn wait_for(
        &mut self,
        within: Duration,
        mut pred: impl FnMut(&Frame) -> bool,
    ) -> Result<Option<(Instant, Frame)>, Finding> {
        let deadline = self.t.now() + within;
        while let Some((t, f)) = self.recv(deadline)? {
            if pred(&f) {
                return Ok(Some((t, f)));
            }
        }
        Ok(None)
    }

    /// Every frame `pred` accepts during the next `during`.
    pub fn collect(
        &mut self,
        during: Duration,
        mut pred: impl FnMut(&Frame) -> bool,
    ) -> Result<Vec<(Instant, Frame)>, Finding> {
        let deadline = self.t.now() + during;
        let mut out = Vec::new();
        while let Some((t, f)) = self.recv(deadline)? {
            if pred(&f) {
                out.push((t, f));
            }
        }
        Ok(out)
    }

    /// Takes, logged, every frame the transport already holds, so that what the next
    /// stimulus is answered with cannot be a frame the bus carried before it.
    pub fn drain(&mut self) -> Result<(), Finding> {
        let now = self.t.now();
        // A transport holds a bounded number of frames; the bound only guards against one
        // that keeps producing frames stamped in the past.
        for _ in 0..100_000 {
            if self.recv(now)?.is_none() {
                break;
            }
        }
        Ok(())
    }

    /// Waits until the bus has been quiet for `quiet` (nothing from the device), for
    /// `within` at most: a device that has just been powered sends its boot-up (CiA 301
    /// §7.3.2.2.1) and maybe EMCYs first, and the first case must not take them for the
    /// answer to its stimulus. Returns whether the bus became quiet.
    pub fn settle(&mut self, quiet: Duration, within: Duration) -> Result<bool, Finding> {
        let end = self.t.now() + within;
        loop {
            let now = self.t.now();
            if now >= end {
                return Ok(false);
            }
            let until = (now + quiet).min(end);
            if self.recv(until)?.is_none() {
                // Nothing from `now` to `until`: quiet if that was the whole period.
                return Ok(now + quiet <= end);
            }
        }
    }

    /// Lets `d` pass, logging what the bus carries.
    pub fn idle(&mut self, d: Duration) -> Result<(), Finding> {
        self.collect(d, |_| false).map(|_| ())
    }

    /// The device's SDO request COB-ID (0x600 + node-ID, CiA 301 §7.3.4).
    pub fn sdo_rx(&self) -> Id {
        id16(cantwin_canopen::wire::SDO_RX_BASE, self.node)
    }

    /// The device's SDO response COB-ID (0x580 + node-ID).
    pub fn sdo_tx(&self) -> Id {
        id16(cantwin_canopen::wire::SDO_TX_BASE, self.node)
    }

    /// The error-control COB-ID (0x700 + node-ID).
    pub fn ec_id(&self) -> Id {
        id16(cantwin_canopen::wire::ERROR_CONTROL_BASE, self.node)
    }

    /// The default EMCY COB-ID (0x080 + node-ID).
    pub fn emcy_id(&self) -> Id {
        id16(cantwin_canopen::wire::EMCY_BASE, self.node)
    }

    /// Sends one raw SDO request and returns the server's answer, if one comes within the
    /// SDO timeout.
    pub fn sdo_raw(&mut self, req: [u8; 8]) -> Result<Option<[u8; 8]>, Finding> {
        let timeout = self.options.sdo_timeout;
        self.drain()?;
        self.send(Frame::data_array(self.sdo_rx(), req))?;
        self.sdo_answer(timeout)
    }

    /// The next SDO response within `within`.
    pub fn sdo_answer(&mut self, within: Duration) -> Result<Option<[u8; 8]>, Finding> {
        let tx = self.sdo_tx();
        let got = self.wait_for(within, |f| f.id() == tx && !f.is_remote())?;
        Ok(got.map(|(_, f)| {
            let mut b = [0u8; 8];
            let d = f.data_bytes();
            b[..d.len().min(8)].copy_from_slice(&d[..d.len().min(8)]);
            b
        }))
    }

    fn client(&self) -> Result<SdoClient, Finding> {
        let mut c = SdoClient::for_node(self.node).map_err(|e| fail(e.to_string()))?;
        c.config_mut().timeout = self.options.sdo_timeout;
        // The conformance cases choose the protocol themselves: no silent fallback.
        c.config_mut().fallback = false;
        Ok(c)
    }

    /// Runs `client`'s transfer to its end. `no_switch`: the transfer is a block upload
    /// whose initiate carries pst = 0, so the server may not answer it with an ordinary
    /// upload (CiA 301 §7.2.4.3.13). The client takes such a switch, as a master should;
    /// a conformance case may not, so the server's first answer is looked at here.
    fn drive(
        &mut self,
        client: &mut SdoClient,
        mut out: Outbox,
        no_switch: bool,
    ) -> Result<Result<Vec<u8>, Aborted>, Finding> {
        let rx = client.rx_id();
        let mut first_answer = no_switch;
        // Every transfer ends at the client's timeout at the latest; the bound only guards
        // against a transport whose clock does not move.
        for _ in 0..1_000_000 {
            for f in out.drain().collect::<Vec<_>>() {
                self.send(f)?;
            }
            while let Some(e) = client.poll_event() {
                match e {
                    SdoEvent::Completed { data, .. } => return Ok(Ok(data)),
                    SdoEvent::Aborted {
                        code, by_server, ..
                    } => {
                        // A client-side abort frame is already queued: send it.
                        for f in out.drain().collect::<Vec<_>>() {
                            self.send(f)?;
                        }
                        return Ok(Err(Aborted { code, by_server }));
                    }
                    SdoEvent::Progress { .. } | SdoEvent::FellBack { .. } => {}
                }
            }
            let Some(deadline) = client.next_deadline() else {
                return Err(fail("the SDO client stopped without an outcome"));
            };
            match self.recv(deadline)? {
                Some((t, f)) => {
                    if f.id() == rx && !f.is_remote() {
                        if std::mem::take(&mut first_answer) {
                            self.switched_protocol(&f)?;
                        }
                        client.on_frame(&f, t, &mut out);
                    }
                }
                None => {
                    let now = self.t.now();
                    client.on_tick(now, &mut out);
                }
            }
        }
        Err(fail("the SDO transfer did not end"))
    }

    /// Fails on `answer` to a block upload initiate with pst = 0 if it is an ordinary upload
    /// initiate response (scs = 2, CiA 301 §7.2.4.3.6): the server switched protocol where
    /// §7.2.4.3.13 allows no switch. The server's ordinary upload is aborted first with
    /// 0x05040001 (§7.2.4.3.17), so that it is idle for what follows.
    fn switched_protocol(&mut self, answer: &Frame) -> Result<(), Finding> {
        let d = answer.data_bytes();
        if d.len() != 8 || d[0] >> 5 != 2 {
            return Ok(());
        }
        let mut abort = [0u8; 8];
        abort[0] = 0x80;
        abort[1..4].copy_from_slice(&d[1..4]);
        abort[4..].copy_from_slice(&AbortCode::INVALID_COMMAND.to_u32().to_le_bytes());
        self.send(Frame::data_array(self.sdo_rx(), abort))?;
        let kind = if d[0] & 0x02 != 0 {
            "an expedited"
        } else {
            "a segmented"
        };
        Err(fail(format!(
            "a block upload initiate with pst = 0 (no change of protocol, CiA 301 §7.2.4.3.13) was answered with {kind} upload ({d:02X?})"
        )))
    }

    /// Reads `index`/`sub` with `mode`.
    pub fn upload_mode(
        &mut self,
        index: u16,
        sub: u8,
        mode: Mode,
        crc: bool,
    ) -> Result<Result<Vec<u8>, Aborted>, Finding> {
        let mut c = self.client()?;
        c.config_mut().crc = crc;
        let no_switch = matches!(mode, Mode::Block { .. }) && c.config_mut().pst == 0;
        let mut out = Outbox::new();
        let now = self.t.now();
        c.start_upload(index, sub, mode, now, &mut out)
            .map_err(|e| fail(e.to_string()))?;
        self.drive(&mut c, out, no_switch)
    }

    /// Writes `data` to `index`/`sub` with `mode`.
    pub fn download_mode(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        mode: Mode,
        crc: bool,
    ) -> Result<Result<(), Aborted>, Finding> {
        let mut c = self.client()?;
        c.config_mut().crc = crc;
        let mut out = Outbox::new();
        let now = self.t.now();
        c.start_download(index, sub, data.to_vec(), mode, now, &mut out)
            .map_err(|e| fail(e.to_string()))?;
        Ok(self.drive(&mut c, out, false)?.map(|_| ()))
    }

    /// Reads with the normal protocol (the server chooses expedited or segmented).
    pub fn upload(&mut self, index: u16, sub: u8) -> Result<Result<Vec<u8>, Aborted>, Finding> {
        self.upload_mode(index, sub, Mode::Segmented, false)
    }

    /// Writes expedited (1–4 bytes) or segmented.
    pub fn download(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
    ) -> Result<Result<(), Aborted>, Finding> {
        let mode = if (1..=4).contains(&data.len()) {
            Mode::Expedited
        } else {
            Mode::Segmented
        };
        self.download_mode(index, sub, data, mode, false)
    }

    /// Reads an unsigned value of up to 4 bytes; a failure names `what`.
    pub fn read_u32(&mut self, index: u16, sub: u8, what: &str) -> Result<u32, Finding> {
        match self.upload(index, sub)? {
            Ok(d) if !d.is_empty() && d.len() <= 4 => {
                let mut b = [0u8; 4];
                b[..d.len()].copy_from_slice(&d);
                Ok(u32::from_le_bytes(b))
            }
            Ok(d) => Err(fail(format!(
                "{what} (0x{index:04X} sub {sub}) read {} bytes, expected 1 to 4",
                d.len()
            ))),
            Err(a) => Err(fail_sdo(
                format!("reading {what} (0x{index:04X} sub {sub})"),
                a,
            )),
        }
    }

    /// Writes `data`, failing the case (naming `what`) if the device refuses.
    pub fn write(&mut self, index: u16, sub: u8, data: &[u8], what: &str) -> Result<(), Finding> {
        match self.download(index, sub, data)? {
            Ok(()) => Ok(()),
            Err(a) => Err(fail_sdo(
                format!("writing {what} (0x{index:04X} sub {sub})"),
                a,
            )),
        }
    }

    /// Sends the NMT command `cs` to the device (CiA 301 §7.2.8.3.1).
    pub fn nmt(&mut self, cs: NmtCs) -> Result<(), Finding> {
        let f = Frame::data_array(id16(0, 0), [cs as u8, self.node]);
        self.send(f)
    }

    /// Sends NMT `cs` and waits for the boot-up message (CiA 301 §7.2.8.3.2.4).
    /// Only a boot-up seen after the command counts: one still queued from before (the
    /// power-up's, an earlier reset's) is not the answer to it.
    pub fn reset(&mut self, cs: NmtCs) -> Result<Option<Instant>, Finding> {
        self.drain()?;
        self.nmt(cs)?;
        let ec = self.ec_id();
        let within = self.options.boot_timeout;
        let got = self.wait_for(within, |f| {
            f.id() == ec && !f.is_remote() && f.data_bytes() == [0]
        })?;
        Ok(got.map(|(t, _)| t))
    }

    /// Resets communication and waits for the boot-up; the case fails without one.
    pub fn fresh(&mut self) -> Result<(), Finding> {
        match self.reset(NmtCs::ResetCommunication)? {
            Some(_) => Ok(()),
            None => Err(fail(
                "no boot-up message after NMT reset communication (CiA 301 §7.2.8.3.2.4)",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;

    use super::*;

    /// A bus on which the device's boot-up is already waiting to be read and the device
    /// answers nothing after that.
    struct Queued {
        now: Instant,
        held: VecDeque<(Instant, Frame)>,
    }

    impl Transport for Queued {
        fn send(&mut self, _frame: Frame) -> Result<(), TransportError> {
            Ok(())
        }
        fn recv(&mut self, deadline: Instant) -> Result<Option<(Instant, Frame)>, TransportError> {
            if let Some(f) = self.held.pop_front() {
                return Ok(Some(f));
            }
            self.now = self.now.max(deadline);
            Ok(None)
        }
        fn now(&self) -> Instant {
            self.now
        }
        fn describe(&self) -> String {
            "queued".into()
        }
    }

    #[test]
    fn a_boot_up_held_from_before_the_reset_is_not_its_answer() {
        let boot_up = Frame::std(0x705, &[0]).unwrap();
        let mut t = Queued {
            now: Instant::from_nanos(10_000_000),
            held: VecDeque::from([(Instant::from_nanos(1_000_000), boot_up)]),
        };
        let eds = Eds::default();
        let profile = Profile::from_eds(&eds);
        let options = Options::default();
        let mut ctx = Ctx::new(&mut t, 5, &eds, &profile, &options);
        assert_eq!(ctx.reset(NmtCs::ResetCommunication), Ok(None));
        // The held boot-up is in the log, before the command.
        let (log, _) = ctx.take_log();
        assert_eq!(log[0].dir, Direction::Response);
        assert_eq!(log[1].dir, Direction::Stimulus);
    }
}
