//! The fuzz target of the CiA 301 frame decoders, driven by `cantwin fuzz`. Not part of the
//! stable interface.

use std::hint::black_box;

use cantwin_can::SplitMix64;
use cantwin_can::fuzz::{below, frame};

use crate::sdo::wire::{BlockSegment, Request, Response};
use crate::wire::{self, Emcy, ErrorControl, NmtCommand, Sync, Time};

/// One case: a random frame through the NMT, error control, SYNC, TIME, EMCY and SDO
/// decoders, and random bytes through the SDO request, response and block segment
/// decoders. Decoders answer bad input with an error, never a panic.
pub fn wire_decoders(rng: &mut SplitMix64) {
    let f = frame(rng, &[]);
    let _ = black_box(NmtCommand::decode(&f));
    let _ = black_box(ErrorControl::decode(&f, below(rng, 128) as u8));
    let _ = black_box(Sync::decode(&f));
    let _ = black_box(Time::decode(&f));
    let _ = black_box(Emcy::decode(&f));
    let m = wire::decode(&f);
    let _ = black_box(m.sdo_request());
    let _ = black_box(m.sdo_response());
    let mut b = [0u8; 8];
    b.iter_mut().for_each(|x| *x = rng.next_u64() as u8);
    let _ = black_box(Request::decode(&b));
    let _ = black_box(Response::decode(&b));
    let _ = black_box(BlockSegment::decode(&b));
}
