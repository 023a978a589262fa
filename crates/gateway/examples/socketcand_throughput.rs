//! Measures what a socketcand client gets through the gateway on the in-memory bus (no bus
//! timing): frames per second from the bus to the client in windows of 1000, and the round
//! trip of a request from the client answered by a node on the bus.
//!
//! `cargo run --release -p cantwin-gateway --example socketcand_throughput`

use std::sync::Arc;
use std::time::{Duration, Instant};

use cantwin_can::Frame;
use cantwin_gateway::memory::MemoryBus;
use cantwin_gateway::socketcand::{Client, Server};
use cantwin_gateway::{BusConnector, BusPort, Limits};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let bus = MemoryBus::new(["vcan0"]);
    let server = Server::bind(
        "127.0.0.1:0".parse()?,
        Arc::new(bus.clone()),
        Limits::default(),
    )?;
    let client = Client::connect(server.local_addr(), "vcan0", Duration::from_secs(5))?;
    let node = bus.open("vcan0", 4096)?;
    let frame = Frame::std(0x181, &[1, 2, 3, 4, 5, 6, 7, 8])?;
    let timeout = Duration::from_secs(5);

    // Bus to client, 1000 frames in flight at most.
    let (windows, window) = (200, 1000);
    let start = Instant::now();
    for _ in 0..windows {
        for _ in 0..window {
            node.send(frame)?;
        }
        for _ in 0..window {
            client.recv_timeout(timeout)?.ok_or("frame lost")?;
        }
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "bus -> socketcand client: {:.0} frames/s ({} frames in {:.3} s)",
        f64::from(windows * window) / secs,
        windows * window,
        secs
    );

    // Client request, node answer, client receives the answer.
    let rounds = 2000;
    let answer = Frame::std(0x581, &[0x43, 0, 0x10, 0, 0x92, 1, 2, 0])?;
    let start = Instant::now();
    for _ in 0..rounds {
        client.send(Frame::std(0x601, &[0x40, 0, 0x10, 0, 0, 0, 0, 0])?)?;
        node.recv_timeout(timeout)?.ok_or("request lost")?;
        node.send(answer)?;
        client.recv_timeout(timeout)?.ok_or("answer lost")?;
    }
    let per = start.elapsed() / rounds;
    println!("request/answer round trip through the gateway: {per:?}");
    server.shutdown();
    Ok(())
}
