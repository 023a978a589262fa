//! Running a sans-IO node over a real port with a clock.
//!
//! A [`Port`] is anything that sends frames and waits for received ones up to an instant
//! of its own clock: a gateway client, a SocketCAN socket, a test double. [`drive`] runs
//! the node's contract against it (frames in, timers, frames out, `on_sent` after each
//! frame the port accepted) until the caller's condition holds. The canopen crate stays a
//! protocol crate: ports live with their transports.

use cantwin_can::{Frame, Instant, Node, Outbox};

/// A CAN port with a clock.
pub trait Port {
    /// A transport error.
    type Error;

    /// The port's current time.
    fn now(&mut self) -> Instant;

    /// Sends a frame (returns once the port has accepted it).
    fn send(&mut self, frame: &Frame) -> Result<(), Self::Error>;

    /// Waits for a received frame until `deadline` (or a port-defined poll interval when
    /// `None`); `None` if nothing arrived.
    fn recv(&mut self, deadline: Option<Instant>) -> Result<Option<(Frame, Instant)>, Self::Error>;
}

/// Sends what `out` holds; every frame the port accepts is confirmed to the node, which
/// may queue more.
fn send_all<N: Node + ?Sized, P: Port>(
    node: &mut N,
    port: &mut P,
    out: &mut Outbox,
) -> Result<(), P::Error> {
    while !out.is_empty() {
        let frames: Vec<Frame> = out.drain().collect();
        for f in frames {
            port.send(&f)?;
            let now = port.now();
            node.on_sent(&f, now, out);
        }
    }
    Ok(())
}

/// Runs `node` on `port` until `done(node)` is true (checked after every step).
pub fn drive<N: Node + ?Sized, P: Port>(
    node: &mut N,
    port: &mut P,
    mut done: impl FnMut(&mut N) -> bool,
) -> Result<(), P::Error> {
    let mut out = Outbox::new();
    loop {
        send_all(node, port, &mut out)?;
        if done(node) {
            return Ok(());
        }
        let now = port.now();
        if node.next_deadline().is_some_and(|d| now >= d) {
            node.on_tick(now, &mut out);
            continue;
        }
        if let Some((frame, at)) = port.recv(node.next_deadline())?
            && node.accepts(frame.id())
        {
            node.on_frame(&frame, at, &mut out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::master::{Master, MasterEvent, Mode, SdoEvent};
    use cantwin_can::Duration;
    use std::collections::VecDeque;

    /// A port with a virtual clock and a server that answers one expedited upload.
    struct Loop {
        now: Instant,
        inbox: VecDeque<Frame>,
        sent: Vec<String>,
    }

    impl Port for Loop {
        type Error = ();
        fn now(&mut self) -> Instant {
            self.now
        }
        fn send(&mut self, frame: &Frame) -> Result<(), ()> {
            self.sent.push(frame.to_string());
            if frame.id().as_raw() == 0x605 {
                self.inbox.push_back(
                    Frame::std(0x585, &[0x4B, 0x17, 0x10, 0, 0xE8, 0x03, 0, 0]).unwrap(),
                );
            }
            Ok(())
        }
        fn recv(&mut self, deadline: Option<Instant>) -> Result<Option<(Frame, Instant)>, ()> {
            let _ = deadline;
            self.now += Duration::from_micros(100);
            Ok(self.inbox.pop_front().map(|f| (f, self.now)))
        }
    }

    #[test]
    fn drive_runs_an_upload_to_completion() {
        let mut port = Loop {
            now: Instant::ZERO,
            inbox: VecDeque::new(),
            sent: Vec::new(),
        };
        let mut m = Master::new();
        let mut out = Outbox::new();
        m.upload(
            5,
            crate::master::Mux::new(0x1017, 0),
            Mode::Auto,
            Instant::ZERO,
            &mut out,
        )
        .unwrap();
        send_all(&mut m, &mut port, &mut out).unwrap();
        let mut got = None;
        drive(&mut m, &mut port, |m| {
            while let Some((_, e)) = m.poll_event() {
                got = Some(e);
            }
            got.is_some()
        })
        .unwrap();
        assert_eq!(port.sent, ["605#4017100000000000"]);
        match got {
            Some(MasterEvent::Sdo {
                event: SdoEvent::Completed { data, .. },
                ..
            }) => assert_eq!(data, [0xE8, 0x03]),
            other => panic!("{other:?}"),
        }
    }
}
