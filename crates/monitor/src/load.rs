//! Bus load over time: bits on the bus per fixed window, from each frame's exact length
//! ([`Frame::bit_length`]: stuff bits and intermission included), against the bits the bit
//! rate allows in a window.

use std::collections::VecDeque;

use cantwin_can::{BitRate, Duration, Frame, Instant};

/// One window of the series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// Its start, a multiple of the window width in bus time.
    pub start: Instant,
    /// Frames that ended in it.
    pub frames: u64,
    /// Their bits on the bus.
    pub bits: u64,
}

/// Windows of bus load, oldest first, at most a fixed number of them.
#[derive(Debug, Clone)]
pub struct LoadSeries {
    bit_rate: BitRate,
    width: Duration,
    capacity: usize,
    windows: VecDeque<Window>,
}

impl LoadSeries {
    /// A series of windows `width` wide (at least 1 µs), keeping the last `capacity` (at
    /// least 1).
    pub fn new(bit_rate: BitRate, width: Duration, capacity: usize) -> LoadSeries {
        LoadSeries {
            bit_rate,
            width: Duration::from_nanos(width.as_nanos().max(1_000)),
            capacity: capacity.max(1),
            windows: VecDeque::new(),
        }
    }

    /// The bit rate the load is measured against.
    pub fn bit_rate(&self) -> BitRate {
        self.bit_rate
    }

    /// The width of a window.
    pub fn width(&self) -> Duration {
        self.width
    }

    fn window_start(&self, at: Instant) -> Instant {
        let w = self.width.as_nanos();
        Instant::from_nanos(at.as_nanos() / w * w)
    }

    /// Advance to `now`: windows up to the one holding `now` exist (empty ones for silent
    /// stretches), older ones beyond the capacity are dropped. Time going backwards is
    /// ignored.
    pub fn advance(&mut self, now: Instant) {
        let start = self.window_start(now);
        let Some(last) = self.windows.back().map(|w| w.start) else {
            self.windows.push_back(Window {
                start,
                frames: 0,
                bits: 0,
            });
            return;
        };
        if start <= last {
            return;
        }
        let w = self.width.as_nanos();
        let missing = (start.as_nanos() - last.as_nanos()) / w;
        // A long silence leaves at most `capacity` empty windows, not one per width.
        let first = if missing > self.capacity as u64 {
            self.windows.clear();
            start.as_nanos() - (self.capacity as u64 - 1) * w
        } else {
            last.as_nanos() + w
        };
        let mut t = first;
        while t <= start.as_nanos() {
            self.windows.push_back(Window {
                start: Instant::from_nanos(t),
                frames: 0,
                bits: 0,
            });
            t += w;
        }
        while self.windows.len() > self.capacity {
            self.windows.pop_front();
        }
    }

    /// Count `frame`, which ended at `at`. A frame older than the newest window counts in
    /// the newest one (a late timestamp from a remote source).
    pub fn record(&mut self, at: Instant, frame: &Frame) {
        self.advance(at);
        if let Some(w) = self.windows.back_mut() {
            w.frames += 1;
            w.bits += u64::from(frame.bit_length());
        }
    }

    /// The windows, oldest first; the last one is still filling.
    pub fn windows(&self) -> impl DoubleEndedIterator<Item = &Window> + ExactSizeIterator {
        self.windows.iter()
    }

    /// The bits a window can hold at the bit rate.
    pub fn capacity_bits(&self) -> f64 {
        f64::from(self.bit_rate.bits_per_second()) * self.width.as_secs_f64()
    }

    /// The load of a window, 0.0–1.0 (more only if timestamps crowd frames together).
    pub fn load(&self, w: &Window) -> f64 {
        w.bits as f64 / self.capacity_bits()
    }

    /// Frames per second in a window.
    pub fn frames_per_second(&self, w: &Window) -> f64 {
        w.frames as f64 / self.width.as_secs_f64()
    }

    /// The load of each window, oldest first.
    pub fn load_series(&self) -> Vec<f64> {
        self.windows.iter().map(|w| self.load(w)).collect()
    }

    /// Frames per second of each window, oldest first.
    pub fn fps_series(&self) -> Vec<f64> {
        self.windows
            .iter()
            .map(|w| self.frames_per_second(w))
            .collect()
    }

    /// The last complete window (the one before the window still filling).
    pub fn last_complete(&self) -> Option<&Window> {
        self.windows.iter().rev().nth(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cantwin_can::Id;

    fn ms(v: u64) -> Instant {
        Instant::from_nanos(v * 1_000_000)
    }

    #[test]
    fn load_is_bits_over_window_capacity() {
        let mut s = LoadSeries::new(BitRate::R500K, Duration::from_millis(100), 10);
        let f = Frame::data(Id::standard(0x181).unwrap(), &[0; 8]).unwrap();
        let bits = u64::from(f.bit_length());
        for i in 0..50 {
            s.record(ms(i), &f);
        }
        s.record(ms(150), &f);
        let w: Vec<Window> = s.windows().copied().collect();
        assert_eq!(w.len(), 2);
        assert_eq!(w[0].frames, 50);
        assert_eq!(w[0].bits, 50 * bits);
        assert_eq!(w[1].start, ms(100));
        // 500 kbit/s × 0.1 s = 50 000 bits.
        assert!((s.load(&w[0]) - (50 * bits) as f64 / 50_000.0).abs() < 1e-12);
        assert!((s.frames_per_second(&w[0]) - 500.0).abs() < 1e-9);
        assert_eq!(s.last_complete(), Some(&w[0]));
    }

    #[test]
    fn silence_makes_empty_windows_and_the_series_is_bounded() {
        let mut s = LoadSeries::new(BitRate::R1M, Duration::from_millis(10), 5);
        let f = Frame::data(Id::standard(0x80).unwrap(), &[]).unwrap();
        s.record(ms(0), &f);
        s.advance(ms(35));
        let frames: Vec<u64> = s.windows().map(|w| w.frames).collect();
        assert_eq!(frames, [1, 0, 0, 0]);
        s.advance(ms(10_000));
        assert_eq!(s.windows().len(), 5);
        assert_eq!(s.windows().last().unwrap().start, ms(10_000));
        assert!(s.windows().all(|w| w.frames == 0));
        // Time going backwards changes nothing; a late frame counts in the newest window.
        s.record(ms(5), &f);
        assert_eq!(s.windows().len(), 5);
        assert_eq!(s.windows().last().unwrap().frames, 1);
        assert_eq!(s.load_series().len(), 5);
        assert_eq!(s.fps_series()[4], 100.0);
    }
}
