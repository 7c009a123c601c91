//! The mutator: turns valid seed inputs into damaged ones, deterministically from a seed and an
//! input index, so the parent process can rebuild any input a worker was running when it died
//! without the worker having to send it.
//!
//! An input is one seed (chosen at random), then 1 to 8 stacked mutations: bit flips, random bytes,
//! interesting integers (both byte orders) and floats, runs of random or repeated bytes inserted,
//! ranges deleted or duplicated, splices of another seed, truncation, and for text inputs tokens of
//! the target's dictionary and numbers written out as text (`1e308`, `-1`, `NaN`, `18446744073709551616`).

/// The simulator's seeded generator (splitmix64, `equiarm_sim::rng::Rng`), one stream per input.
#[derive(Clone, Debug)]
pub struct Rng(equiarm_sim::rng::Rng);

impl Rng {
    /// A generator for input `index` of a run with `seed` on the target named `target`.
    pub fn for_input(seed: u64, target: &str, index: u64) -> Self {
        let mut h = 0xcbf2_9ce4_8422_2325u64; // FNV-1a of the target name
        for b in target.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
        Rng(equiarm_sim::rng::Rng::new(seed ^ h.rotate_left(17) ^ index.wrapping_mul(0x9e37_79b9_7f4a_7c15)))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// A number in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 { 0 } else { (self.next_u64() % n as u64) as usize }
    }

    /// True with probability `1/n`.
    pub fn one_in(&mut self, n: usize) -> bool {
        self.below(n) == 0
    }
}

/// Integers that sit on boundaries: lengths, counts, sizes and signs go wrong there.
const INTERESTING: [u64; 20] = [
    0,
    1,
    2,
    3,
    4,
    7,
    8,
    16,
    0x7f,
    0x80,
    0xff,
    0x100,
    0x7fff,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    0x1_0000_0000,
    0x7fff_ffff_ffff_ffff,
    u64::MAX,
];

/// Floats that break arithmetic: NaN, the infinities, signed zero, extremes and subnormals.
const FLOATS: [f64; 12] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    -0.0,
    0.0,
    -1.0,
    1e-300,
    1e300,
    f64::MAX,
    f64::MIN_POSITIVE,
    f32::MAX as f64,
    5e-324,
];

/// Numbers written out as text, for JSON, XML attributes and command lines.
const NUMBER_TEXT: [&str; 24] = [
    "0",
    "-0",
    "1",
    "-1",
    "0.5",
    "1e308",
    "-1e308",
    "1e-300",
    "1e999",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "Infinity",
    "4294967295",
    "4294967296",
    "2147483648",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "1e12",
    "100000000",
    "3.4028235e38",
    "",
];

/// How a target's inputs are shaped, which decides the mutations worth trying.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// Binary data: byte-level mutations only.
    Binary,
    /// Text (JSON, XML, a command-line word): byte-level mutations plus dictionary tokens and
    /// numbers written as text.
    Text,
}

/// Rebuilds and mutates inputs for one target.
#[derive(Clone, Debug)]
pub struct Mutator {
    seeds: Vec<Vec<u8>>,
    dictionary: Vec<Vec<u8>>,
    shape: Shape,
    max_len: usize,
}

impl Mutator {
    /// A mutator of `seeds` (at least one) for inputs of `shape`, never longer than `max_len`
    /// bytes (or the longest seed, whichever is larger); `dictionary` holds tokens of the format
    /// (keys, tags, keywords) that text mutations insert.
    pub fn new(seeds: Vec<Vec<u8>>, dictionary: &[&str], shape: Shape, max_len: usize) -> Self {
        let longest = seeds.iter().map(Vec::len).max().unwrap_or(0);
        Mutator {
            seeds,
            dictionary: dictionary.iter().map(|t| t.as_bytes().to_vec()).collect(),
            shape,
            max_len: max_len.max(longest),
        }
    }

    /// The seeds.
    pub fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    /// Input `index` of a run with `seed` on `target`: the same arguments always give the same
    /// bytes. The first inputs of a run are the seeds themselves, unmutated.
    pub fn input(&self, seed: u64, target: &str, index: u64) -> Vec<u8> {
        if self.seeds.is_empty() {
            return Vec::new();
        }
        if (index as usize) < self.seeds.len() {
            return self.seeds[index as usize].clone();
        }
        let mut rng = Rng::for_input(seed, target, index);
        let mut data = self.seeds[rng.below(self.seeds.len())].clone();
        let mut rounds = 1;
        while rounds < 8 && rng.one_in(2) {
            rounds += 1;
        }
        for _ in 0..rounds {
            self.mutate_once(&mut rng, &mut data);
        }
        data.truncate(self.max_len);
        data
    }

    fn mutate_once(&self, rng: &mut Rng, data: &mut Vec<u8>) {
        let kinds = if self.shape == Shape::Text { 14 } else { 11 };
        match rng.below(kinds) {
            0 => flip_bit(rng, data),
            1 => random_byte(rng, data),
            2 => interesting_int(rng, data),
            3 => interesting_float(rng, data),
            4 => insert_bytes(rng, data),
            5 => delete_range(rng, data),
            6 => duplicate_range(rng, data),
            7 => self.splice(rng, data),
            8 => truncate(rng, data),
            9 => {
                // a few flips close together: damage within one field
                let at = rng.below(data.len().max(1));
                for _ in 0..1 + rng.below(4) {
                    if let Some(b) = data.get_mut(at + rng.below(8)) {
                        *b ^= 1 << rng.below(8);
                    }
                }
            }
            10 => arithmetic(rng, data),
            11 => self.dictionary_token(rng, data),
            12 => number_text(rng, data),
            _ => replace_number(rng, data),
        }
    }

    fn splice(&self, rng: &mut Rng, data: &mut Vec<u8>) {
        let other = &self.seeds[rng.below(self.seeds.len())];
        if other.is_empty() {
            return;
        }
        let from = rng.below(other.len());
        let len = 1 + rng.below(other.len() - from);
        let piece = &other[from..from + len];
        let at = rng.below(data.len() + 1);
        if rng.one_in(2) {
            // the tail of this input replaced by a piece of another
            data.truncate(at);
            data.extend_from_slice(piece);
        } else {
            data.splice(at..at, piece.iter().copied());
        }
    }

    fn dictionary_token(&self, rng: &mut Rng, data: &mut Vec<u8>) {
        const GENERIC: [&str; 14] = ["\"", "{", "}", "[", "]", ",", ":", "null", "true", "false", "<", ">", "/>", "="];
        let token: Vec<u8> = if !self.dictionary.is_empty() && rng.one_in(2) {
            self.dictionary[rng.below(self.dictionary.len())].clone()
        } else {
            GENERIC[rng.below(GENERIC.len())].as_bytes().to_vec()
        };
        let at = rng.below(data.len() + 1);
        if rng.one_in(2) || data.is_empty() {
            data.splice(at..at, token);
        } else {
            let end = (at + token.len()).min(data.len());
            data.splice(at..end, token);
        }
    }
}

fn flip_bit(rng: &mut Rng, data: &mut [u8]) {
    if !data.is_empty() {
        let at = rng.below(data.len());
        data[at] ^= 1 << rng.below(8);
    }
}

fn random_byte(rng: &mut Rng, data: &mut [u8]) {
    if !data.is_empty() {
        let at = rng.below(data.len());
        data[at] = rng.next_u64() as u8;
    }
}

fn overwrite(rng: &mut Rng, data: &mut Vec<u8>, bytes: &[u8]) {
    if data.len() < bytes.len() {
        data.extend_from_slice(bytes);
        return;
    }
    // aligned half of the time: CDR and safetensors fields sit at multiples of their size
    let slots = data.len() - bytes.len() + 1;
    let mut at = rng.below(slots);
    if rng.one_in(2) {
        at -= at % bytes.len();
    }
    data[at..at + bytes.len()].copy_from_slice(bytes);
}

fn interesting_int(rng: &mut Rng, data: &mut Vec<u8>) {
    let mut v = INTERESTING[rng.below(INTERESTING.len())];
    if rng.one_in(4) {
        v = v.wrapping_neg();
    }
    let width = [1usize, 2, 4, 8][rng.below(4)];
    let bytes = if rng.one_in(3) { v.to_be_bytes()[8 - width..].to_vec() } else { v.to_le_bytes()[..width].to_vec() };
    overwrite(rng, data, &bytes);
}

fn interesting_float(rng: &mut Rng, data: &mut Vec<u8>) {
    let v = FLOATS[rng.below(FLOATS.len())];
    let bytes = if rng.one_in(2) { (v as f32).to_le_bytes().to_vec() } else { v.to_le_bytes().to_vec() };
    overwrite(rng, data, &bytes);
}

fn arithmetic(rng: &mut Rng, data: &mut [u8]) {
    if data.is_empty() {
        return;
    }
    let at = rng.below(data.len());
    let delta = 1 + rng.below(35) as u8;
    data[at] = if rng.one_in(2) { data[at].wrapping_add(delta) } else { data[at].wrapping_sub(delta) };
}

fn insert_bytes(rng: &mut Rng, data: &mut Vec<u8>) {
    let most = if rng.one_in(8) { 256 } else { 16 };
    let n = 1 + rng.below(most);
    let at = rng.below(data.len() + 1);
    let bytes: Vec<u8> =
        if rng.one_in(2) { vec![rng.next_u64() as u8; n] } else { (0..n).map(|_| rng.next_u64() as u8).collect() };
    data.splice(at..at, bytes);
}

fn delete_range(rng: &mut Rng, data: &mut Vec<u8>) {
    if data.is_empty() {
        return;
    }
    let at = rng.below(data.len());
    let most = if rng.one_in(4) { 1024 } else { 16 };
    let n = 1 + rng.below((data.len() - at).min(most));
    data.drain(at..at + n);
}

fn duplicate_range(rng: &mut Rng, data: &mut Vec<u8>) {
    if data.is_empty() {
        return;
    }
    let from = rng.below(data.len());
    let n = 1 + rng.below((data.len() - from).min(64));
    let piece = data[from..from + n].to_vec();
    let at = rng.below(data.len() + 1);
    data.splice(at..at, piece);
}

fn truncate(rng: &mut Rng, data: &mut Vec<u8>) {
    let at = rng.below(data.len() + 1);
    data.truncate(at);
}

fn number_text(rng: &mut Rng, data: &mut Vec<u8>) {
    let text = NUMBER_TEXT[rng.below(NUMBER_TEXT.len())];
    let at = rng.below(data.len() + 1);
    data.splice(at..at, text.bytes());
}

/// Replaces a number already in the text (a run of digits, signs, dots and exponents) by another.
fn replace_number(rng: &mut Rng, data: &mut Vec<u8>) {
    let is_num = |b: u8| b.is_ascii_digit() || matches!(b, b'-' | b'+' | b'.' | b'e' | b'E');
    let starts: Vec<usize> = (0..data.len())
        .filter(|&i| {
            data[i].is_ascii_digit() && (i == 0 || !is_num(data[i - 1]))
                || (data[i] == b'-' && i + 1 < data.len() && data[i + 1].is_ascii_digit())
        })
        .collect();
    if starts.is_empty() {
        number_text(rng, data);
        return;
    }
    let start = starts[rng.below(starts.len())];
    let mut end = start + 1;
    while end < data.len() && is_num(data[end]) {
        end += 1;
    }
    let text = NUMBER_TEXT[rng.below(NUMBER_TEXT.len())];
    data.splice(start..end, text.bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mutator(shape: Shape) -> Mutator {
        let seeds = vec![br#"{"batch_size": 64, "agent": {"lr": 0.003}}"#.to_vec(), vec![0u8; 40]];
        Mutator::new(seeds, &["\"num_envs\""], shape, 4096)
    }

    #[test]
    fn the_same_index_always_gives_the_same_input() {
        let m = mutator(Shape::Text);
        for i in 0..500 {
            assert_eq!(m.input(7, "t", i), m.input(7, "t", i), "input {i}");
        }
    }

    #[test]
    fn seeds_come_first_then_mutants_that_differ() {
        let m = mutator(Shape::Binary);
        assert_eq!(m.input(1, "t", 0), m.seeds()[0]);
        assert_eq!(m.input(1, "t", 1), m.seeds()[1]);
        let changed = (2..1002).filter(|&i| !m.seeds().contains(&m.input(1, "t", i))).count();
        assert!(changed > 900, "only {changed} of 1000 inputs differ from every seed");
        // other seeds and other targets give other inputs
        assert_ne!(
            (2..50).map(|i| m.input(1, "t", i)).collect::<Vec<_>>(),
            (2..50).map(|i| m.input(2, "t", i)).collect::<Vec<_>>()
        );
        assert_ne!(
            (2..50).map(|i| m.input(1, "t", i)).collect::<Vec<_>>(),
            (2..50).map(|i| m.input(1, "u", i)).collect::<Vec<_>>()
        );
    }

    #[test]
    fn inputs_respect_the_length_limit() {
        let m = Mutator::new(vec![vec![1u8; 100]], &[], Shape::Binary, 120);
        assert!((0..5000).all(|i| m.input(3, "t", i).len() <= 120));
    }

    #[test]
    fn text_mutations_replace_numbers_by_boundary_values() {
        let m = mutator(Shape::Text);
        let texts: Vec<String> = (2..5000).map(|i| String::from_utf8_lossy(&m.input(5, "t", i)).into_owned()).collect();
        for wanted in ["1e308", "18446744073709551616", "NaN", "\"num_envs\""] {
            assert!(texts.iter().any(|t| t.contains(wanted) && t.starts_with("{\"")), "no input with {wanted}");
        }
    }
}
