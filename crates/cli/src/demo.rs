//! `cantwin demo`: the embedded default scenario, run in virtual time with no files and no
//! setup, printing what happened on the wire.
//!
//! The network grows as device twins arrive; today it shows the physical layer every twin
//! stands on: arbitration, exact frame timing, remote frames, injected corruption with
//! retransmission, a babbling node forced bus-off, a power cycle, and a node alone on a bus
//! that nobody acknowledges.

use anyhow::{Context, Result};
use cantwin_bus::{
    BusConfig, BusEvent, BusId, ErrorKind, FaultRule, FrameSelector, PortConfig, PortId, Recorder,
    Simulation, TapId,
};
use cantwin_can::{
    BitRate, ControllerEvent, Duration, ErrorCounters, Frame, Id, Instant, Node, Outbox,
};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print every frame of the physical-layer part, not only the first cycle and the
    /// interesting events.
    #[arg(long, short)]
    verbose: bool,
    /// Run only these parts (default: all, in this order).
    #[arg(long, value_enum, value_delimiter = ',')]
    only: Vec<Part>,
}

/// The parts of the demo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    /// Arbitration, timing, errors and faults on the virtual bus.
    Physical,
    /// A CiA 301 device twin and cantwin's CANopen master.
    Canopen,
    /// The ADV200 drive twin in the manual's worked example.
    Adv200,
    /// The ADV200 on DeviceNet under cantwin's scanner.
    Devicenet,
    /// The TM3 I/O coupler twin under cantwin's CANopen master.
    Tm3,
    /// The OPEN DRIVE twin under a CAL master.
    Opendrive,
}

pub fn run(args: &Args) -> Result<()> {
    let parts = if args.only.is_empty() {
        vec![
            Part::Physical,
            Part::Canopen,
            Part::Adv200,
            Part::Devicenet,
            Part::Tm3,
            Part::Opendrive,
        ]
    } else {
        args.only.clone()
    };
    let wall = std::time::Instant::now();
    for (i, part) in parts.iter().enumerate() {
        if i > 0 {
            println!("\n{}\n", "-".repeat(78));
        }
        match part {
            Part::Physical => physical(args)?,
            Part::Canopen => crate::demo_canopen::run()?,
            Part::Adv200 => crate::demo_adv200::run()?,
            Part::Devicenet => crate::demo_devicenet::run()?,
            Part::Tm3 => crate::demo_tm3::run()?,
            Part::Opendrive => crate::demo_opendrive::run()?,
        }
    }
    println!(
        "\nDemo finished in {:.0} ms of wall time. Next: `cantwin sim scenarios/cia301-device.toml --socketcand 29536`.",
        wall.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

/// Sends a counter on its identifier every `period`, starting at power-up.
struct Periodic {
    id: Id,
    period: Duration,
    next: Option<Instant>,
    counter: u16,
}

impl Periodic {
    fn new(raw: u16, period: Duration) -> Result<Self> {
        Ok(Periodic {
            id: Id::standard(raw)?,
            period,
            next: None,
            counter: 0,
        })
    }
}

impl Node for Periodic {
    fn on_power_up(&mut self, now: Instant, out: &mut Outbox) {
        self.counter = 0;
        self.next = Some(now);
        self.on_tick(now, out);
    }
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        if let Some(next) = self.next.filter(|n| *n <= now) {
            out.push(Frame::data_array(self.id, self.counter.to_le_bytes()));
            self.counter = self.counter.wrapping_add(1);
            self.next = Some(next + self.period);
        }
    }
    fn next_deadline(&self) -> Option<Instant> {
        self.next
    }
    fn accepts(&self, _id: Id) -> bool {
        false
    }
}

/// Answers a remote frame on its identifier with the number of requests seen so far.
struct Responder {
    id: Id,
    answered: u32,
}

impl Node for Responder {
    fn on_frame(&mut self, frame: &Frame, _now: Instant, out: &mut Outbox) {
        if frame.is_remote() && frame.id() == self.id {
            self.answered += 1;
            out.push(Frame::data_array(self.id, self.answered.to_le_bytes()));
        }
    }
    fn on_tick(&mut self, _now: Instant, _out: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
    fn accepts(&self, id: Id) -> bool {
        id == self.id
    }
}

/// Sends a remote frame every `period`.
struct Requester {
    id: Id,
    period: Duration,
    next: Instant,
}

impl Node for Requester {
    fn on_frame(&mut self, _frame: &Frame, _now: Instant, _out: &mut Outbox) {}
    fn on_tick(&mut self, now: Instant, out: &mut Outbox) {
        if now >= self.next {
            if let Ok(f) = Frame::remote(self.id, 4) {
                out.push(f);
            }
            self.next += self.period;
        }
    }
    fn next_deadline(&self) -> Option<Instant> {
        Some(self.next)
    }
    fn accepts(&self, id: Id) -> bool {
        id == self.id
    }
}

struct Network {
    sim: Simulation,
    can0: BusId,
    can1: BusId,
    tap0: TapId,
    tap1: TapId,
    names: Vec<(PortId, &'static str)>,
    shown: [usize; 2],
    /// A mirror of each port's transmit error counter, replayed from the events so every
    /// printed error frame shows the TEC right after it (ISO 11898-1 §12.1.4).
    tec: Vec<(PortId, ErrorCounters)>,
}

impl Network {
    fn name(&self, port: PortId) -> &'static str {
        self.names
            .iter()
            .find(|(p, _)| *p == port)
            .map(|(_, n)| *n)
            .unwrap_or("?")
    }

    fn counters(&mut self, port: PortId) -> &mut ErrorCounters {
        let i = match self.tec.iter().position(|(p, _)| *p == port) {
            Some(i) => i,
            None => {
                self.tec.push((port, ErrorCounters::new()));
                self.tec.len() - 1
            }
        };
        &mut self.tec[i].1
    }

    /// Print the events of can0 since the last call, in bus order. Frames of the periodic
    /// sensors after `quiet_after` and babble after its first two frames are counted rather
    /// than printed, unless `verbose`.
    fn print_new(&mut self, verbose: bool, quiet_after: Instant) -> Result<()> {
        let b = self.sim.bus(self.can0).context("can0")?;
        let rec = b.tap::<Recorder>(self.tap0).context("recorder")?;
        let events = rec.events[self.shown[0]..].to_vec();
        self.shown[0] = rec.events.len();
        let (mut periodic, mut babble) = (0u32, 0u32);
        for e in events {
            match e {
                BusEvent::Frame(f) => {
                    self.counters(f.sender).on_transmit_success();
                    let name = self.name(f.sender);
                    let sensor = matches!(name, "sensor-a" | "sensor-b" | "beacon");
                    if f.babble {
                        babble += 1;
                        if babble > 2 && !verbose {
                            continue;
                        }
                    } else if sensor && !verbose && f.start >= quiet_after {
                        periodic += 1;
                        continue;
                    }
                    println!(
                        "  {:>12}  {:<18} {:<10} {:>3} bits  {}",
                        f.end.to_string(),
                        f.frame.to_string(),
                        name,
                        f.bits,
                        if f.babble {
                            "babble"
                        } else if f.frame.is_remote() {
                            "remote frame"
                        } else {
                            ""
                        },
                    );
                }
                BusEvent::Error(r) => {
                    let why = match r.kind {
                        ErrorKind::Ack => "no acknowledgement",
                        ErrorKind::Corrupted => "bit error (injected corruption)",
                        ErrorKind::BitRateMismatch => "bit rate mismatch",
                        ErrorKind::Aborted => "transmitter went bus-off mid-frame",
                    };
                    let tec = if r.kind == ErrorKind::Aborted {
                        String::new()
                    } else {
                        let c = self.counters(r.sender);
                        c.on_transmit_error(r.kind == ErrorKind::Ack);
                        format!("; TEC {}", c.tec())
                    };
                    println!(
                        "  {:>12}  {:<18} {:<10} ERROR FRAME: {why}{tec}",
                        r.detected.to_string(),
                        r.frame.to_string(),
                        self.name(r.sender),
                    );
                }
                BusEvent::Controller { port, event, at } => {
                    println!(
                        "  {:>12}  {:<18} {:<10} {}",
                        at.to_string(),
                        "",
                        self.name(port),
                        describe(event)
                    );
                }
            }
        }
        if babble > 2 && !verbose {
            println!("  {:>12}  … {} more babble frames", "", babble - 2);
        }
        if periodic > 0 {
            println!(
                "  {:>12}  … {periodic} periodic sensor frames (--verbose shows them)",
                ""
            );
        }
        Ok(())
    }
}

fn describe(event: ControllerEvent) -> &'static str {
    match event {
        ControllerEvent::ErrorPassive => "controller error-passive",
        ControllerEvent::ErrorActive => "controller error-active again",
        ControllerEvent::BusOff => "controller BUS-OFF",
        ControllerEvent::BusOffRecovered => {
            "controller recovered from bus-off (128 x 11 recessive bits)"
        }
        ControllerEvent::RxOverrun => "receive overrun",
        ControllerEvent::TxDropped => "transmit queue full: frame dropped",
    }
}

fn build() -> Result<Network> {
    let mut sim = Simulation::new();
    let can0 = sim.add_bus(BusConfig::new("can0", BitRate::R500K).with_seed(2024));
    let can1 = sim.add_bus(BusConfig::new("can1", BitRate::R125K).with_seed(2024));
    let ms = Duration::from_millis;
    let mut names = Vec::new();
    let sensor_a = sim.attach(can0, Periodic::new(0x182, ms(100))?, PortConfig::default())?;
    names.push((sensor_a, "sensor-a"));
    let sensor_b = sim.attach(can0, Periodic::new(0x181, ms(100))?, PortConfig::default())?;
    names.push((sensor_b, "sensor-b"));
    let beacon = sim.attach(can0, Periodic::new(0x701, ms(250))?, PortConfig::default())?;
    names.push((beacon, "beacon"));
    let responder = Responder {
        id: Id::standard(0x285)?,
        answered: 0,
    };
    let resp = sim.attach(can0, responder, PortConfig::default())?;
    names.push((resp, "responder"));
    let requester = Requester {
        id: Id::standard(0x285)?,
        period: ms(250),
        next: Instant::ZERO + ms(50),
    };
    let req = sim.attach(can0, requester, PortConfig::default())?;
    names.push((req, "requester"));
    let lonely = sim.attach(can1, Periodic::new(0x123, ms(2000))?, PortConfig::default())?;
    names.push((lonely, "lonely"));
    let tap0 = sim.bus_mut(can0).context("can0")?.add_tap(Recorder::new());
    let tap1 = sim.bus_mut(can1).context("can1")?.add_tap(Recorder::new());
    Ok(Network {
        sim,
        can0,
        can1,
        tap0,
        tap1,
        names,
        shown: [0, 0],
        tec: Vec::new(),
    })
}

fn port_named(net: &Network, name: &str) -> Result<PortId> {
    net.names
        .iter()
        .find(|(_, n)| *n == name)
        .map(|(p, _)| *p)
        .with_context(|| format!("no node {name}"))
}

fn physical(args: &Args) -> Result<()> {
    let wall = std::time::Instant::now();
    let mut net = build()?;
    let ms = |v: u64| Instant::ZERO + Duration::from_millis(v);
    let v = args.verbose;
    let can0 = net.can0;
    let sensor_a = port_named(&net, "sensor-a")?;
    let sensor_b = port_named(&net, "sensor-b")?;

    println!("The physical layer: two virtual CAN buses, 1 s of bus time in virtual time.");
    println!(
        "  can0 500 kbit/s: sensor-a (0x182) and sensor-b (0x181) every 100 ms, beacon (0x701)"
    );
    println!(
        "                   every 250 ms, a requester polling a responder (0x285) by remote frame"
    );
    println!("  can1 125 kbit/s: one node alone, which nobody acknowledges");
    println!("Times are the end of each frame's EOF, in seconds of bus time.\n");

    println!("t = 0: everyone powers up and queues a frame at once. The lowest identifier wins");
    println!("arbitration; each frame takes its exact stuffed length on the wire:");
    net.sim.run_until(ms(60));
    net.print_new(v, ms(1))?;

    println!("\nt = 200 ms: the next 3 frames of sensor-a (0x182) are corrupted on the wire; the");
    println!("sender sees the bit error, sends an error flag, and retransmits:");
    net.sim.run_until(ms(200));
    net.print_new(v, Instant::ZERO)?;
    net.sim
        .bus_mut(can0)
        .context("can0")?
        .inject(FaultRule::corrupt(FrameSelector::Id(Id::standard(0x182)?)).times(3));
    net.sim.run_until(ms(210));
    net.print_new(v, Instant::MAX)?;

    println!(
        "\nt = 400 ms: sensor-b's controller babbles 0x000, the highest priority, and starves"
    );
    println!("the bus until it is forced bus-off 1 ms later; it recovers by itself:");
    net.sim.run_until(ms(400));
    net.print_new(v, Instant::ZERO)?;
    let babble = Frame::std(0x000, &[0xBA, 0xBB])?;
    let bus = net.sim.bus_mut(can0).context("can0")?;
    bus.set_babble(sensor_b, Some(babble))?;
    net.sim.run_until(ms(401));
    let bus = net.sim.bus_mut(can0).context("can0")?;
    bus.set_babble(sensor_b, None)?;
    bus.force_bus_off(sensor_b)?;
    net.sim.run_until(ms(410));
    net.print_new(v, Instant::ZERO)?;

    println!("\nt = 600 ms: sensor-a loses power for 150 ms and restarts its counter at power-up:");
    net.sim.run_until(ms(600));
    net.print_new(v, Instant::ZERO)?;
    net.sim
        .bus_mut(can0)
        .context("can0")?
        .set_powered(sensor_a, false)?;
    net.sim.run_until(ms(750));
    net.sim
        .bus_mut(can0)
        .context("can0")?
        .set_powered(sensor_a, true)?;
    net.sim.run_until(ms(1000));
    net.print_new(v, ms(751))?;

    println!("\nOn can1 the lonely node's first frame is never acknowledged:");
    lonely_story(&net)?;

    println!("\nAfter 1 s of bus time:");
    for bus in [net.can0, net.can1] {
        let b = net.sim.bus(bus).context("bus")?;
        let now = b.now();
        let s = b.stats();
        println!(
            "  {} ({}): {} frames, {} error frames, bus load {:.1} %",
            b.name(),
            b.bit_rate(),
            s.frames(),
            s.error_frames(),
            s.load_percent(now)
        );
        for port in b.ports().collect::<Vec<_>>() {
            if let Ok(st) = b.port_status(port) {
                println!(
                    "    {:<10} TEC {:>3}  REC {:>3}  {:?}",
                    net.name(port),
                    st.counters.tec(),
                    st.counters.rec(),
                    st.counters.state(),
                );
            }
        }
    }
    let resp = port_named(&net, "responder")?;
    let answered = net
        .sim
        .node::<Responder>(resp)
        .map(|r| r.answered)
        .unwrap_or(0);
    println!("  the responder answered {answered} remote frames");
    println!(
        "\nSimulated 1 s of two buses in {:.1} ms of wall time.",
        wall.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

/// Summarise can1: a node alone sees ACK errors, counts them up to error-passive, and then
/// (an error-passive transmitter does not count ACK errors) retransmits forever.
fn lonely_story(net: &Network) -> Result<()> {
    let b = net.sim.bus(net.can1).context("can1")?;
    let rec = b.tap::<Recorder>(net.tap1).context("recorder")?;
    let mut counters = ErrorCounters::new();
    let mut shown = 0;
    for e in &rec.events {
        match e {
            BusEvent::Error(r) => {
                counters.on_transmit_error(r.kind == ErrorKind::Ack);
                if shown < 2 {
                    shown += 1;
                    println!(
                        "  {:>12}  {:<18} {:<10} ERROR FRAME: no acknowledgement; TEC {}",
                        r.detected.to_string(),
                        r.frame.to_string(),
                        net.name(r.sender),
                        counters.tec()
                    );
                }
            }
            BusEvent::Controller { port, event, at } => println!(
                "  {:>12}  {:<18} {:<10} {} (TEC {})",
                at.to_string(),
                "",
                net.name(*port),
                describe(*event),
                counters.tec()
            ),
            BusEvent::Frame(_) => {}
        }
    }
    println!(
        "  {:>12}  … {} error frames in all: error-passive transmitters do not count ACK errors,",
        "",
        rec.errors().count()
    );
    println!(
        "  {:>12}    so it stays error-passive and retransmits until someone answers",
        ""
    );
    Ok(())
}
