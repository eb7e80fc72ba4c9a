//! The quoting rule, as a property: an error may quote a short prefix of
//! its input, never more (`docs/protocol.md`: messages quote at most a
//! 64-character prefix of any input). An error that echoes its input
//! swells with it: a 63 MB TOML line once made a 190 MB message, which
//! overflowed the status header and reached the client as the wrong code.

/// Longest run of input bytes a message may repeat verbatim.
pub const MAX_ECHO_BYTES: usize = 64;

/// Longest message, in characters: the server cuts a status message there
/// (`server/src/error.rs`), so anything past it, such as what to change,
/// would never reach the client.
pub const MAX_MESSAGE_CHARS: usize = 1024;

/// Panics when `message` repeats more than [`MAX_ECHO_BYTES`] consecutive
/// bytes of `input`, or is longer than [`MAX_MESSAGE_CHARS`].
///
/// Rabin–Karp: the hashes of every window of `MAX_ECHO_BYTES + 1` input
/// bytes go into a sorted list, each window of the message is looked up
/// in it, and only a hit is compared byte for byte, so the check costs a
/// pass over each rather than their product.
///
/// # Panics
/// On either breach, showing the start of the repeated run.
pub fn assert_quotes_briefly(input: &[u8], message: &str) {
    let chars = message.chars().count();
    assert!(
        chars <= MAX_MESSAGE_CHARS,
        "a {chars}-character message, over the {MAX_MESSAGE_CHARS} a status keeps: {}...",
        message.chars().take(200).collect::<String>()
    );
    let window = MAX_ECHO_BYTES + 1;
    let message = message.as_bytes();
    if input.len() < window || message.len() < window {
        return;
    }
    let mut seen: Vec<u64> = hashes(input, window).map(|(_, h)| h).collect();
    seen.sort_unstable();
    for (start, hash) in hashes(message, window) {
        let run = &message[start..start + window];
        if seen.binary_search(&hash).is_ok() && input.windows(window).any(|w| w == run) {
            panic!(
                "the message repeats {window} bytes of the input: {:?} in {:?}",
                String::from_utf8_lossy(run),
                String::from_utf8_lossy(&message[..message.len().min(400)])
            );
        }
    }
}

/// The rolling hash of each `window`-byte window of `bytes`, with its
/// start.
fn hashes(bytes: &[u8], window: usize) -> impl Iterator<Item = (usize, u64)> + '_ {
    const BASE: u64 = 0x100_0000_01b3;
    let top = (1..window).fold(1u64, |p, _| p.wrapping_mul(BASE));
    let first = bytes[..window].iter().fold(0u64, |h, &b| {
        h.wrapping_mul(BASE).wrapping_add(u64::from(b))
    });
    let rolled = (window..bytes.len()).scan(first, move |h, end| {
        let out = u64::from(bytes[end - window]);
        *h = h
            .wrapping_sub(out.wrapping_mul(top))
            .wrapping_mul(BASE)
            .wrapping_add(u64::from(bytes[end]));
        Some((end + 1 - window, *h))
    });
    std::iter::once((0, first)).chain(rolled)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_quote_passes() {
        let input = "x".repeat(5000);
        assert_quotes_briefly(
            input.as_bytes(),
            &format!("bad value {:?}...", &input[..60]),
        );
    }

    #[test]
    #[should_panic(expected = "repeats 65 bytes")]
    fn a_long_echo_anywhere_in_the_message_fails() {
        let input: String = (0..300)
            .map(|i| char::from(b'a' + (i * 7 % 26) as u8))
            .collect();
        assert_quotes_briefly(
            input.as_bytes(),
            &format!("at line 3: {}", &input[100..170]),
        );
    }

    #[test]
    #[should_panic(expected = "over the 1024")]
    fn an_overlong_message_fails() {
        assert_quotes_briefly(b"", &"y".repeat(2000));
    }
}
