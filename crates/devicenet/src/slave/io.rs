//! Polled I/O (DeviceNet Vol. 1, "Poll command / response") and the inactivity watchdogs
//! of every connection (4 × expected packet rate), plus the explicit fragment timers.

use super::Slave;
use crate::fragment::TxProgress;
use crate::objects::connection::{
    ConnState, Connection, WATCHDOG_AUTO_DELETE, WATCHDOG_AUTO_RESET,
};
use crate::objects::{Application, SlaveEvent};
use crate::wire::{self, choice};
use cantwin_can::{Instant, Outbox};

impl<A: Application> Slave<A> {
    // ----- polled I/O -----

    pub(super) fn on_poll(&mut self, data: &[u8], now: Instant, out: &mut Outbox) {
        let Some(c) = self.poll.as_mut() else { return };
        if c.state != ConnState::Established {
            return;
        }
        c.kick(now);
        let command = if c.consumed_size > 8 && !data.is_empty() {
            match c.io_rx.on_frame(data) {
                Some(d) => d,
                None => return,
            }
        } else {
            data.to_vec()
        };
        if !command.is_empty() && command.len() != usize::from(c.consumed_size) {
            let expected = c.consumed_size;
            let received = u16::try_from(command.len()).unwrap_or(u16::MAX);
            self.app
                .event(SlaveEvent::IoLengthMismatch { received, expected }, now);
            return;
        }
        c.idle = command.is_empty();
        let (produced_size, id) = (usize::from(c.produced_size), c.produced_id);
        self.app.consume(&command, now);
        let mut input = self.app.produce(now);
        input.resize(produced_size, 0);
        if produced_size > 8 {
            for f in wire::io_fragments(&input) {
                out.push(id.frame(&f));
            }
        } else {
            out.push(id.frame(&input));
        }
    }

    // ----- watchdogs -----

    pub(super) fn watchdogs(&mut self, now: Instant) {
        if self
            .explicit
            .as_ref()
            .and_then(Connection::watchdog_deadline)
            .is_some_and(|d| now >= d)
        {
            self.app
                .event(SlaveEvent::ExplicitTimedOut { instance: 1 }, now);
            self.release_bits(choice::EXPLICIT, now);
        }
        if let Some(c) = self.poll.as_mut() {
            if c.watchdog_deadline().is_some_and(|d| now >= d) {
                match c.watchdog_action {
                    WATCHDOG_AUTO_DELETE => {
                        self.app.event(SlaveEvent::IoTimedOut, now);
                        self.release_bits(choice::POLLED, now);
                    }
                    WATCHDOG_AUTO_RESET => c.kick(now),
                    _ => {
                        c.state = ConnState::TimedOut;
                        self.app.event(SlaveEvent::IoTimedOut, now);
                    }
                }
            }
        }
        let mut i = 0;
        while i < self.ucmm.len() {
            if self.ucmm[i].watchdog_deadline().is_some_and(|d| now >= d) {
                let instance = self.ucmm.remove(i).instance;
                self.app
                    .event(SlaveEvent::ExplicitTimedOut { instance }, now);
            } else {
                i += 1;
            }
        }
    }

    pub(super) fn fragment_timers(&mut self, now: Instant, out: &mut Outbox) {
        let conns = self.explicit.iter_mut().chain(self.ucmm.iter_mut());
        for c in conns {
            if let Some(tx) = c.tx.as_mut() {
                match tx.on_tick(now) {
                    Some(TxProgress::Send(f)) => out.push(c.produced_id.frame(&f)),
                    Some(TxProgress::Aborted) => c.tx = None,
                    _ => {}
                }
            }
        }
    }
}
