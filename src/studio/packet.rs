//! What the page receives for its views: a JSON head and typed arrays in
//! one body. Layout: a little-endian u32 length, the JSON, spaces to a
//! multiple of 4 bytes, then each array the head lists (`arrays`: name,
//! type f32/u32, length) in turn, little-endian.

use crate::grid::Grid;
use serde_json::{json, Value};

pub struct Packet {
    head: Value,
    arrays: Vec<(String, &'static str, Vec<u8>, usize)>,
}

impl Packet {
    pub fn new(head: Value) -> Packet {
        Packet {
            head,
            arrays: Vec::new(),
        }
    }

    pub fn f32(mut self, name: &str, v: &[f32]) -> Packet {
        let bytes = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.arrays.push((name.into(), "f32", bytes, v.len()));
        self
    }

    pub fn u32(mut self, name: &str, v: &[u32]) -> Packet {
        let bytes = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.arrays.push((name.into(), "u32", bytes, v.len()));
        self
    }

    pub fn bytes(self) -> Vec<u8> {
        let mut head = self.head;
        head["arrays"] = self
            .arrays
            .iter()
            .map(|(n, t, _, len)| json!({"name": n, "type": t, "len": len}))
            .collect();
        let mut j = serde_json::to_vec(&head).expect("head serializes");
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let mut out =
            Vec::with_capacity(4 + j.len() + self.arrays.iter().map(|a| a.2.len()).sum::<usize>());
        out.extend((j.len() as u32).to_le_bytes());
        out.extend(j);
        for (_, _, b, _) in self.arrays {
            out.extend(b);
        }
        out
    }
}

/// A grid brought down to at most `max` samples on its long side by whole
/// blocks: NaN where a block has no number, else `pick` of its numbers.
pub fn shrink(g: &Grid<f32>, max: usize, pick: fn(&[f32]) -> f32) -> Grid<f32> {
    let k = g.w.max(g.h).div_ceil(max.max(1)).max(1);
    if k == 1 {
        return g.clone();
    }
    let (w, h) = (g.w.div_ceil(k), g.h.div_ceil(k));
    let mut out = Grid::new(w, h, f32::NAN);
    let mut block = Vec::with_capacity(k * k);
    for y in 0..h {
        for x in 0..w {
            block.clear();
            for yy in y * k..((y + 1) * k).min(g.h) {
                for xx in x * k..((x + 1) * k).min(g.w) {
                    let v = *g.get(xx, yy);
                    if !v.is_nan() {
                        block.push(v);
                    }
                }
            }
            if !block.is_empty() {
                out.set(x, y, pick(&block));
            }
        }
    }
    out
}

/// The mean of a block.
pub fn mean(v: &[f32]) -> f32 {
    v.iter().sum::<f32>() / v.len() as f32
}

/// The number of a block farthest from zero (a gouge or a ridge left is
/// shown, not averaged away).
pub fn extreme(v: &[f32]) -> f32 {
    v.iter()
        .copied()
        .fold(0.0, |a, b| if b.abs() > a.abs() { b } else { a })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn head_then_aligned_arrays() {
        let b = Packet::new(json!({"w": 2}))
            .f32("h", &[1.5, -2.0])
            .u32("i", &[7])
            .bytes();
        let n = u32::from_le_bytes(b[..4].try_into().unwrap()) as usize;
        assert_eq!(n % 4, 0);
        let head: Value = serde_json::from_slice(&b[4..4 + n]).unwrap();
        assert_eq!(head["w"], 2);
        assert_eq!(head["arrays"][1]["name"], "i");
        let a = &b[4 + n..];
        assert_eq!(f32::from_le_bytes(a[4..8].try_into().unwrap()), -2.0);
        assert_eq!(u32::from_le_bytes(a[8..12].try_into().unwrap()), 7);
    }

    #[test]
    fn shrinking_keeps_the_extreme() {
        let mut g = Grid::new(5, 3, 0.0f32);
        g.set(4, 2, -0.5);
        g.set(0, 0, f32::NAN);
        let s = shrink(&g, 2, extreme);
        assert_eq!((s.w, s.h), (2, 1));
        assert_eq!(*s.get(1, 0), -0.5);
        assert_eq!(*s.get(0, 0), 0.0);
    }
}
