//! The CiA 401 generic I/O device profile, reusable by any I/O device: the objects
//! ([`objects`]), the input events ([`inputs`]: change of state of digital inputs, the
//! analog interrupt triggers of 0x6421) and the outputs' reaction to a device or
//! communication failure ([`outputs`]: error mode and error value, "safe positions").
//!
//! The profile is a set of pure functions and small state machines over an
//! [`ObjectDictionary`](cantwin_canopen::od::ObjectDictionary): a device model keeps its
//! physical inputs and outputs, writes inputs through [`inputs`] (which says whether an
//! event-driven TPDO is due) and reads its physical outputs through [`outputs`].
//!
//! ```
//! use std::sync::Arc;
//! use cantwin_canopen::od::{ObjectDictionary, OdBuilder, Value};
//! use cantwin_cia401::{IoLayout, inputs, objects, outputs};
//!
//! let layout = IoLayout { digital_input_bytes: 1, digital_output_bytes: 1, analog_inputs: 0, analog_outputs: 0 };
//! let desc = objects::add_objects(OdBuilder::new(), &layout).build().expect("valid");
//! let mut od = ObjectDictionary::new(Arc::new(desc), 1);
//! // Input 3 goes high: 0x6006 (any change) is 0xFF by default, so a TPDO is due.
//! assert!(inputs::set_digital_input_byte(&mut od, 1, 0b0000_1000));
//! assert_eq!(od.get(0x6000, 1), Ok(Value::Unsigned8(0b0000_1000)));
//! // Outputs written by the master; on a communication failure, 0x6206 = 0xFF and
//! // 0x6207 = 0 switch them all off.
//! od.set(0x6200, 1, &Value::Unsigned8(0xA5)).expect("exists");
//! assert_eq!(outputs::digital_output_byte(&od, 1, false), 0xA5);
//! assert_eq!(outputs::digital_output_byte(&od, 1, true), 0x00);
//! ```
#![forbid(unsafe_code)]

pub mod inputs;
pub mod objects;
pub mod outputs;

pub use objects::IoLayout;
