//! The fuzz target of the capture readers, driven by `cantwin fuzz`. Not part of the stable
//! interface.

use std::io::Cursor;

use cantwin_can::SplitMix64;
use cantwin_can::fuzz::{below, bytes, mutate};

use crate::CaptureReader;

/// A small valid capture of a random format: pcap, pcapng or candump log.
pub fn capture_seed(rng: &mut SplitMix64) -> Vec<u8> {
    let pcap_header: [u8; 24] = [
        0xD4, 0xC3, 0xB2, 0xA1, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4, 0, 227, 0, 0, 0,
    ];
    match below(rng, 3) {
        0 => {
            let mut v = pcap_header.to_vec();
            // One record: ts, caplen 16, len 16, SocketCAN header + 8 bytes.
            v.extend_from_slice(&[1, 0, 0, 0, 2, 0, 0, 0, 16, 0, 0, 0, 16, 0, 0, 0]);
            v.extend_from_slice(&[0, 0, 0x01, 0x23, 8, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8]);
            v
        }
        1 => {
            // pcapng: section header block, interface description block (LINKTYPE 227).
            let mut v = vec![
                0x0A, 0x0D, 0x0D, 0x0A, 28, 0, 0, 0, 0x4D, 0x3C, 0x2B, 0x1A, 1, 0, 0, 0,
            ];
            v.extend_from_slice(&[0xFF; 8]);
            v.extend_from_slice(&[28, 0, 0, 0]);
            v.extend_from_slice(&[
                1, 0, 0, 0, 20, 0, 0, 0, 227, 0, 0, 0, 0, 0, 4, 0, 20, 0, 0, 0,
            ]);
            v
        }
        _ => b"(1700000000.000000) can0 123#1122334455667788\n(1700000000.100000) can0 705#7F\n"
            .to_vec(),
    }
}

/// One case: a damaged capture (random bytes, or a mutated valid one) read to its end.
pub fn readers(rng: &mut SplitMix64) {
    let seed = capture_seed(rng);
    let text = String::from_utf8_lossy(&seed).into_owned();
    let input = if below(rng, 8) == 0 {
        bytes(rng, 256)
    } else {
        let mut m = mutate(rng, &text);
        if !seed.is_ascii() {
            // Lossy text would have replaced the binary bytes: mutate the bytes directly.
            m = seed.clone();
            for _ in 0..1 + below(rng, 6) {
                if m.is_empty() {
                    break;
                }
                let i = below(rng, m.len() as u64) as usize;
                match below(rng, 3) {
                    0 => m[i] = rng.next_u64() as u8,
                    1 => m.truncate(i),
                    _ => m.extend(bytes(rng, 40)),
                }
            }
        }
        m
    };
    if let Ok(reader) = CaptureReader::new(Cursor::new(input)) {
        // Bounded: a damaged length field must not make the reader loop forever.
        for record in reader.take(10_000) {
            if record.is_err() {
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mutations start from valid inputs, so the campaigns reach past the headers.
    #[test]
    fn every_seed_input_is_valid() {
        let mut rng = SplitMix64::new(1);
        let mut formats = std::collections::BTreeSet::new();
        for _ in 0..64 {
            let seed = capture_seed(&mut rng);
            let reader = CaptureReader::new(Cursor::new(seed)).unwrap();
            formats.insert(format!("{:?}", reader.format()));
            let records: Vec<_> = reader.collect::<Result<_, _>>().unwrap();
            assert!(records.len() <= 2);
        }
        assert_eq!(formats.len(), 3, "{formats:?}");
    }
}
