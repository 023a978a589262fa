//! A frame-by-frame decoder for listings (`cantwin dump --decode`): one line per frame, by
//! the protocol its channel carries, as `cantwin trace` decodes a live bus. It keeps what a
//! line needs from earlier frames: which nodes were sent a node guarding request, so that
//! their answers are named as guarding rather than heartbeat (CiA 301 §7.2.8.3.2), and each
//! DeviceNet slave's message body format, from its Allocate exchange.

use std::collections::{BTreeMap, BTreeSet};

use cantwin_can::Frame;
use cantwin_canopen::wire::{self, ErrorControl, Message};

use crate::{Options, Protocol, cal, canopen, devicenet};

/// Decodes frames one after the other.
#[derive(Debug)]
pub struct Decoder<'o> {
    opts: &'o Options,
    /// (channel, node) pairs with a guard request waiting for its answer.
    guarded: BTreeSet<(String, u8)>,
    /// DeviceNet slaves' body formats, per channel.
    formats: BTreeMap<String, devicenet::BodyFormats>,
}

impl<'o> Decoder<'o> {
    /// A decoder using `opts`' protocols per channel and PDO mappings.
    pub fn new(opts: &'o Options) -> Self {
        Decoder {
            opts,
            guarded: BTreeSet::new(),
            formats: BTreeMap::new(),
        }
    }

    /// One line for `frame`, seen on `channel` (empty for CANopen frames outside the
    /// pre-defined connection set that no PDO mapping or LSS claims).
    pub fn describe(&mut self, channel: &str, frame: &Frame) -> String {
        match self.opts.protocol(channel) {
            Protocol::CanOpen => self.canopen(channel, frame),
            Protocol::DeviceNet => self
                .formats
                .entry(channel.to_string())
                .or_default()
                .describe(frame),
            Protocol::Cal => cal::describe(frame),
        }
    }

    fn canopen(&mut self, channel: &str, frame: &Frame) -> String {
        match wire::decode(frame) {
            Message::ErrorControl(ErrorControl::GuardRequest { node }) => {
                self.guarded.insert((channel.to_string(), node));
            }
            Message::ErrorControl(ErrorControl::State {
                node,
                state,
                toggle,
            }) if canopen::describe_pdo(frame, &self.opts.pdos).is_none() => {
                let asked = self.guarded.remove(&(channel.to_string(), node));
                return canopen::error_control(node, state, toggle, asked || toggle);
            }
            _ => {}
        }
        canopen::describe(frame, &self.opts.pdos)
    }
}

#[cfg(test)]
mod tests {
    use cantwin_can::Id;

    use super::*;

    fn f(id: u16, data: &[u8]) -> Frame {
        Frame::data(Id::standard(id).unwrap(), data).unwrap()
    }

    #[test]
    fn each_channel_decodes_by_its_protocol() {
        let mut opts = Options::default();
        opts.protocols.insert("dnet".into(), Protocol::DeviceNet);
        opts.protocols.insert("cal".into(), Protocol::Cal);
        let mut d = Decoder::new(&opts);
        assert_eq!(
            d.describe("can0", &f(0x705, &[0x05])),
            "HEARTBEAT node 5 operational"
        );
        assert_eq!(
            d.describe("dnet", &f(0x3C5, &[0x10, 0x20])),
            "G1 msg 15 from MAC 5: slave poll response / COS-cyclic acknowledge: 10 20"
        );
        assert_eq!(
            d.describe("cal", &f(0x181, &[0x85, 0x10, 0x27])),
            "COB 0x181 control 0x85 (bit 7 1, multiplexor 5) data 10 27"
        );
        // Every channel not named: the default protocol.
        let all_cal = Options {
            default_protocol: Protocol::Cal,
            ..Options::default()
        };
        assert!(
            Decoder::new(&all_cal)
                .describe("x", &f(0x705, &[5]))
                .starts_with("COB 0x705")
        );
    }

    #[test]
    fn cia301_7_2_8_3_2_1_a_guarding_answer_is_named_by_the_request_before_it() {
        let opts = Options::default();
        let mut d = Decoder::new(&opts);
        let rtr = Frame::remote(Id::standard(0x70A).unwrap(), 1).unwrap();
        assert_eq!(d.describe("can0", &rtr), "NODE GUARD request node 10");
        assert_eq!(
            d.describe("can0", &f(0x70A, &[0x05])),
            "NODE GUARD response node 10 operational (toggle 0)"
        );
        // On another channel the same node is not guarded.
        d.describe("can1", &rtr);
        assert_eq!(
            d.describe("can0", &f(0x70A, &[0x05])),
            "HEARTBEAT node 10 operational"
        );
    }

    #[test]
    fn devicenet_body_formats_are_learned_per_channel() {
        let opts = Options {
            default_protocol: Protocol::DeviceNet,
            ..Options::default()
        };
        let mut d = Decoder::new(&opts);
        // MAC 12 on "a" is allocated with body format 8/16; on "b" it is not.
        d.describe("a", &f(0x466, &[0x40, 0x4B, 0x03, 0x01, 0x01, 0x00]));
        d.describe("a", &f(0x463, &[0x40, 0xCB, 0x01]));
        let get = f(0x464, &[0x00, 0x0E, 0x01, 0x01, 0x00, 0x07]);
        assert_eq!(
            d.describe("a", &get),
            "G2 MAC 12 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 7 [MAC 0]"
        );
        assert_eq!(
            d.describe("b", &get),
            "G2 MAC 12 msg 4: master explicit request: Get_Attribute_Single (0x0E) class 0x01 instance 1 attribute 0 data 07 [MAC 0]"
        );
    }
}
