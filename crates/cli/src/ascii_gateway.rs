//! `cantwin gateway --ascii`: a CiA 309-3 ASCII gateway in the command syntax of
//! CANopenNode's gateway and its `cocomm` client (parsed and answered by `cantwin-cia309`),
//! on stdin/stdout or TCP.
//!
//! One gateway serves one network (a request's net is taken and not used). The bus is driven
//! by one master and one LSS master (CiA 305) on the gateway's thread; each client has its
//! own default node, SDO timeout and block setting.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::time::Duration as WallDuration;

use anyhow::{Context, Result, bail};
use cantwin_can::{Duration, Frame, Node, Outbox};
use cantwin_canopen::lss;
use cantwin_canopen::master::{Master, MasterEvent, Mode, SdoEvent, TransferId};
use cantwin_cia309::{BusOp, EOL, GwError, LSS_TIMEOUT_MS, LssOp, LssResult, Session, Step};

use crate::connect::{Link, Target};

/// The longest request line accepted, in bytes.
pub const MAX_LINE: usize = 1024;
/// The most TCP clients served at once.
pub const MAX_CLIENTS: usize = 4;

/// Arguments of `cantwin gateway`.
#[derive(Debug, clap::Args)]
pub struct GatewayArgs {
    #[command(flatten)]
    target: Target,
    /// Speak the CiA 309-3 ASCII protocol: the default and the only one offered, so the
    /// option changes nothing (kept for the command lines that give it).
    #[arg(long)]
    ascii: bool,
    /// Serve TCP clients on [ADDR:]PORT (ADDR defaults to 127.0.0.1; port 0 picks one)
    /// instead of reading stdin.
    #[arg(long, value_name = "[ADDR:]PORT")]
    listen: Option<String>,
    /// The SDO timeout each client starts with, in milliseconds.
    #[arg(long, default_value_t = 1000)]
    sdo_timeout: u32,
}

/// A bus operation sent to the gateway's thread, with the client's settings and where the
/// result goes.
struct Job {
    op: BusOp,
    timeout: Duration,
    mode: Mode,
    reply: Sender<JobResult>,
}

/// The result of a job: an SDO transfer's or NMT command's, or an LSS operation's.
enum JobResult {
    Sdo(Result<Vec<u8>, GwError>),
    Lss(Result<LssResult, GwError>),
}

/// Answers one request line; bus operations go to `jobs`.
fn answer(line: &str, s: &mut Session, jobs: &Sender<Job>) -> String {
    match cantwin_cia309::request(line, s) {
        Step::Answer(text) => text,
        Step::Bus(pending) => match run_job(pending.op().clone(), s, jobs) {
            Ok(JobResult::Sdo(r)) => pending.finish(r),
            Ok(JobResult::Lss(r)) => pending.finish_lss(r),
            Err(e) => pending.finish(Err(e)),
        },
    }
}

/// Hands `op` to the gateway's thread with the client's settings and waits for the result.
fn run_job(op: BusOp, s: &Session, jobs: &Sender<Job>) -> Result<JobResult, GwError> {
    let (tx, rx) = mpsc::channel();
    let job = Job {
        op,
        timeout: Duration::from_millis(u64::from(s.sdo_timeout_ms)),
        mode: if s.block {
            Mode::Block { blksize: 127 }
        } else {
            Mode::Auto
        },
        reply: tx,
    };
    jobs.send(job).map_err(|_| GwError::STATE)?;
    rx.recv().map_err(|_| GwError::STATE)
}

/// Puts the frames `node` queued in `out` on the bus and confirms each to it once sent, then
/// the frames that releases: the master hands the driver at most its transmit window of
/// unconfirmed frames ([`Node::on_sent`]), so a frame sent and not confirmed would hold its
/// place for good and, after a window's worth of requests, stop every transfer.
fn send_confirmed<N: Node>(link: &Link, node: &mut N, out: &mut Outbox) -> Result<()> {
    while !out.is_empty() {
        let frames: Vec<Frame> = out.drain().collect();
        for f in frames {
            link.send(f)?;
            node.on_sent(&f, link.now(), out);
        }
    }
    Ok(())
}

/// Runs one LSS service to its end on the bus.
fn lss_service(
    link: &mut Link,
    master: &mut lss::Master,
    service: lss::Service,
    timeout_ms: u16,
) -> Result<Result<lss::Outcome, GwError>> {
    let timeout = Duration::from_millis(u64::from(timeout_ms));
    master.set_timeout(timeout);
    let mut out = Outbox::new();
    if master.start(service, link.now(), &mut out).is_err() {
        return Ok(Err(GwError::STATE));
    }
    send_confirmed(link, master, &mut out)?;
    let mut outcome = master.poll();
    if outcome.is_none() {
        // A fastscan is at most 2 + 4 × 33 steps of one timeout each.
        let limit =
            WallDuration::from_millis(u64::from(timeout_ms)) * 140 + WallDuration::from_secs(1);
        link.run(
            master,
            |m| {
                outcome = m.poll();
                outcome.is_some()
            },
            limit,
        )?;
    }
    Ok(outcome.ok_or(GwError::TIMEOUT))
}

/// Runs an LSS operation: one service, or `lss_allnodes`' cycle of fastscan, configure
/// node-ID, store and switch state global waiting per node found.
fn execute_lss(
    link: &mut Link,
    master: &mut lss::Master,
    op: LssOp,
) -> Result<Result<LssResult, GwError>> {
    let (timeout_ms, start, store, plan) = match op {
        LssOp::Service {
            service,
            timeout_ms,
        } => {
            return Ok(lss_service(link, master, service, timeout_ms)?.map(LssResult::Outcome));
        }
        LssOp::AllNodes {
            timeout_ms,
            start,
            store,
            plan,
        } => (timeout_ms, start, store, plan),
    };
    let mut assigned = Vec::new();
    let mut id = start;
    let refused = |o: lss::Outcome, code: GwError| match o {
        lss::Outcome::Done => Ok(()),
        lss::Outcome::Timeout => Err(GwError::TIMEOUT),
        lss::Outcome::Refused { error: 0xFF, .. } => Err(GwError::LSS_MANUFACTURER),
        _ => Err(code),
    };
    let end = loop {
        let scan = lss::Service::FastscanWith(plan);
        let address = match lss_service(link, master, scan, timeout_ms)? {
            Ok(lss::Outcome::Address(a)) => a,
            Ok(lss::Outcome::Timeout) => break Ok(true),
            Ok(_) => break Err(GwError::STATE),
            Err(e) => break Err(e),
        };
        let set = lss_service(
            link,
            master,
            lss::Service::ConfigureNodeId(id),
            LSS_TIMEOUT_MS,
        )?;
        if let Err(e) = set.and_then(|o| refused(o, GwError::LSS_NODE_ID)) {
            break Err(e);
        }
        if store {
            let stored = lss_service(
                link,
                master,
                lss::Service::StoreConfiguration,
                LSS_TIMEOUT_MS,
            )?;
            if let Err(e) = stored.and_then(|o| refused(o, GwError::LSS_STORE)) {
                break Err(e);
            }
        }
        let waiting = lss::Service::SwitchGlobal(lss::Mode::Waiting);
        if let Err(e) = lss_service(link, master, waiting, LSS_TIMEOUT_MS)? {
            break Err(e);
        }
        assigned.push((id, address));
        if id >= 127 {
            break Ok(false);
        }
        id += 1;
    };
    Ok(Ok(LssResult::AllNodes { assigned, end }))
}

/// Runs `op` on the bus; the master's own SDO timeout ends a transfer that gets no answer.
fn execute(
    link: &mut Link,
    master: &mut Master,
    lss_master: &mut lss::Master,
    job: &Job,
) -> Result<JobResult> {
    let mut out = Outbox::new();
    master.config_mut().sdo.timeout = job.timeout;
    let started = match &job.op {
        BusOp::Nmt { node, cs } => {
            let r = master.nmt(*cs, *node, &mut out);
            send_confirmed(link, master, &mut out)?;
            return Ok(JobResult::Sdo(
                r.map(|()| Vec::new()).map_err(|_| GwError::NODE),
            ));
        }
        BusOp::Lss(op) => return Ok(JobResult::Lss(execute_lss(link, lss_master, *op)?)),
        BusOp::Upload { node, mux } => master.upload(*node, *mux, job.mode, link.now(), &mut out),
        BusOp::Download { node, mux, data } => {
            master.download(*node, *mux, data.clone(), job.mode, link.now(), &mut out)
        }
    };
    let id: TransferId = match started {
        Ok(id) => id,
        Err(_) => return Ok(JobResult::Sdo(Err(GwError::STATE))),
    };
    send_confirmed(link, master, &mut out)?;
    let mut result = None;
    let limit = WallDuration::from_nanos(job.timeout.as_nanos()) * 4 + WallDuration::from_secs(600);
    link.run(
        master,
        |m| {
            while let Some((_, ev)) = m.poll_event() {
                if let MasterEvent::Sdo { id: got, event, .. } = ev
                    && got == id
                {
                    match event {
                        SdoEvent::Completed { data, .. } => result = Some(Ok(data)),
                        SdoEvent::Aborted { code, .. } => result = Some(Err(GwError::Abort(code))),
                        _ => {}
                    }
                }
            }
            result.is_some()
        },
        limit,
    )?;
    Ok(JobResult::Sdo(result.unwrap_or(Err(GwError::TIMEOUT))))
}

/// Drives the bus: runs jobs one at a time and keeps the master fed between them (so the
/// link's receive queue stays short and a job waits at most 10 ms), until every client is
/// gone.
fn serve_bus(link: &mut Link, jobs: &Receiver<Job>) -> Result<()> {
    let mut master = Master::new();
    let mut lss_master = lss::Master::new(Duration::from_millis(u64::from(LSS_TIMEOUT_MS)));
    loop {
        match jobs.try_recv() {
            Ok(job) => {
                let r = execute(link, &mut master, &mut lss_master, &job)?;
                // A client that left does not take an answer.
                let _ = job.reply.send(r);
            }
            Err(TryRecvError::Empty) => {
                link.run(
                    &mut master,
                    |m| {
                        while m.poll_event().is_some() {}
                        false
                    },
                    WallDuration::from_millis(10),
                )?;
            }
            Err(TryRecvError::Disconnected) => return Ok(()),
        }
    }
}

/// Reads one line of at most [`MAX_LINE`] bytes: `None` at the end of input, `Some(Err(()))`
/// for a longer line (whose rest is skipped).
fn read_line(r: &mut impl BufRead) -> std::io::Result<Option<Result<String, ()>>> {
    let mut buf = Vec::new();
    let n = r
        .by_ref()
        .take(MAX_LINE as u64 + 1)
        .read_until(b'\n', &mut buf)?;
    if n == 0 {
        return Ok(None);
    }
    if buf.last() != Some(&b'\n') && buf.len() > MAX_LINE {
        loop {
            let mut skip = Vec::new();
            let n = r.by_ref().take(4096).read_until(b'\n', &mut skip)?;
            if n == 0 || skip.last() == Some(&b'\n') {
                break;
            }
        }
        return Ok(Some(Err(())));
    }
    Ok(Some(
        String::from_utf8(buf)
            .map_err(|_| ())
            .map(|s| s.trim_end().to_owned()),
    ))
}

/// Serves one client: lines in, answers out, each answer ended by [`EOL`] (CR LF, on
/// stdin/stdout as on TCP, as CANopenNode's gateway ends every response whatever carries it)
/// and written in one piece: `cocomm` takes the first read that holds a CR LF as the whole
/// answer, so an answer and its CR LF sent apart (two TCP segments) read as two.
fn serve_client(
    input: &mut impl BufRead,
    output: &mut impl Write,
    jobs: &Sender<Job>,
    mut session: Session,
) -> std::io::Result<()> {
    while let Some(line) = read_line(input)? {
        let mut text = match line {
            Ok(l) => answer(&l, &mut session, jobs),
            Err(()) => format!("[{}] ERROR:{}", session.sequence as i32, GwError::SYNTAX),
        };
        text.push_str(EOL);
        output.write_all(text.as_bytes())?;
        output.flush()?;
    }
    Ok(())
}

fn listen_addr(spec: &str) -> String {
    if spec.contains(':') {
        spec.to_owned()
    } else {
        format!("127.0.0.1:{spec}")
    }
}

/// Runs `cantwin gateway`.
pub fn run(args: &GatewayArgs) -> Result<()> {
    // CiA 309-3 ASCII is the only protocol: `--ascii` is accepted and changes nothing.
    let _ = args.ascii;
    if args.sdo_timeout == 0 {
        bail!("--sdo-timeout must be greater than 0");
    }
    let session = Session::new(args.sdo_timeout);
    let mut link = Link::open(&args.target)?;
    let (jobs, rx) = mpsc::channel::<Job>();
    match &args.listen {
        None => {
            std::thread::spawn(move || {
                let stdin = std::io::stdin();
                let mut input = stdin.lock();
                let mut output = std::io::stdout();
                if let Err(e) = serve_client(&mut input, &mut output, &jobs, session) {
                    eprintln!("gateway: {e}");
                }
            });
        }
        Some(spec) => {
            let addr = listen_addr(spec);
            let listener = TcpListener::bind(&addr)
                .with_context(|| format!("--listen {spec}: binding {addr}"))?;
            let local = listener.local_addr().context("the listening address")?;
            println!("gateway {local}");
            std::io::stdout().flush().context("writing to stdout")?;
            std::thread::spawn(move || accept(&listener, &jobs, session));
        }
    }
    serve_bus(&mut link, &rx)
}

/// Accepts TCP clients, at most [`MAX_CLIENTS`] at once.
fn accept(listener: &TcpListener, jobs: &Sender<Job>, session: Session) {
    let clients = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else {
            continue;
        };
        if clients.fetch_add(1, Ordering::SeqCst) >= MAX_CLIENTS {
            clients.fetch_sub(1, Ordering::SeqCst);
            let _ = writeln!(
                stream,
                "[0] ERROR:{} # the gateway serves at most {MAX_CLIENTS} clients\r",
                GwError::STATE
            );
            continue;
        }
        let jobs = jobs.clone();
        let clients = Arc::clone(&clients);
        std::thread::spawn(move || {
            if let Err(e) = serve_tcp(stream, &jobs, session) {
                eprintln!("gateway client: {e}");
            }
            clients.fetch_sub(1, Ordering::SeqCst);
        });
    }
}

fn serve_tcp(stream: TcpStream, jobs: &Sender<Job>, session: Session) -> std::io::Result<()> {
    let mut output = stream.try_clone()?;
    let mut input = BufReader::new(stream);
    serve_client(&mut input, &mut output, jobs, session)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_lines_are_refused_and_skipped() {
        let text = format!("{}\n[1] help\n", "x".repeat(MAX_LINE + 10));
        let mut r = std::io::Cursor::new(text.into_bytes());
        assert_eq!(read_line(&mut r).unwrap(), Some(Err(())));
        assert_eq!(read_line(&mut r).unwrap(), Some(Ok("[1] help".into())));
        assert_eq!(read_line(&mut r).unwrap(), None);
    }
}
