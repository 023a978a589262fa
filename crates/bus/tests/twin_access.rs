//! A node attached as a twin is reached as `dyn Twin` through the bus and the simulation,
//! without its type; frames it sends while changed from above are queued on its port.

#![allow(clippy::unwrap_used)]

use cantwin_bus::{BoxedNode, BusConfig, PortConfig, Recorder, Simulation};
use cantwin_can::{BitRate, Frame, Instant, ListenOnly, Node, Outbox};
use cantwin_twin::{Context, Direction, SignalError, SignalId, SignalValue, Twin};

/// Sends a frame with its switch's position whenever the switch is set.
#[derive(Default)]
struct Switch {
    on: bool,
}

impl Node for Switch {
    fn on_frame(&mut self, _: &Frame, _: Instant, _: &mut Outbox) {}
    fn on_tick(&mut self, _: Instant, _: &mut Outbox) {}
    fn next_deadline(&self) -> Option<Instant> {
        None
    }
}

impl Twin for Switch {
    fn set_signal(
        &mut self,
        id: &SignalId,
        value: &SignalValue,
        cx: &mut Context<'_>,
    ) -> Result<(), SignalError> {
        if id.as_str() != "switch" {
            return Err(SignalError::unknown(id, Direction::Set, "switch"));
        }
        self.on = value.to_bool(id)?;
        if let Ok(f) = Frame::std(0x100, &[u8::from(self.on)]) {
            cx.out.push(f);
        }
        Ok(())
    }

    fn read_signal(&self, id: &SignalId) -> Result<SignalValue, SignalError> {
        match id.as_str() {
            "switch" => Ok(SignalValue::Bool(self.on)),
            _ => Err(SignalError::unknown(id, Direction::Read, "switch")),
        }
    }
}

#[test]
fn a_twin_is_reached_by_port_and_its_frames_go_out() {
    let mut sim = Simulation::new();
    let bus = sim.add_bus(BusConfig::new("can0", BitRate::R1M));
    let b = sim.bus_mut(bus).unwrap();
    let switch = b.attach_node(BoxedNode::twin(Switch::default()), PortConfig::default());
    let listener = b.attach_node(BoxedNode::plain(ListenOnly), PortConfig::default());
    let tap = b.add_tap(Recorder::new());
    assert!(sim.twin(listener).is_none());
    let id = SignalId::new("switch");
    sim.with_twin(switch, |t, cx| {
        t.set_signal(&id, &SignalValue::Bool(true), cx)
    })
    .unwrap()
    .unwrap();
    assert_eq!(
        sim.twin(switch).unwrap().read_signal(&id),
        Ok(SignalValue::Bool(true))
    );
    sim.run_until(Instant::from_nanos(1_000_000));
    let frames: Vec<String> = sim
        .bus(bus)
        .and_then(|b| b.tap::<Recorder>(tap))
        .unwrap()
        .frames()
        .map(|f| f.frame.to_string())
        .collect();
    assert_eq!(frames, ["100#01"]);
    // Detached, the port is no twin any more.
    sim.bus_mut(bus).unwrap().detach(switch).unwrap();
    assert!(sim.twin(switch).is_none());
}
