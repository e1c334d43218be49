//! `--link`: where the board is.

use std::fmt;

/// The baud rate of the board's USART1 (the firmware's and the emulated board's).
pub const DEFAULT_BAUD: u32 = 115_200;

/// A board reached over TCP (the emulated board under `cargo pil serve`) or a serial port (a
/// board on a USB-UART adapter).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LinkAddress {
    /// `tcp:HOST:PORT`.
    Tcp { host: String, port: u16 },
    /// `serial:PATH[:BAUD]`.
    Serial { path: String, baud: u32 },
}

impl fmt::Display for LinkAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkAddress::Tcp { host, port } => write!(f, "tcp:{host}:{port}"),
            LinkAddress::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
        }
    }
}

impl LinkAddress {
    /// Parses `tcp:HOST:PORT` or `serial:PATH[:BAUD]`; the error says what was expected.
    pub fn parse(text: &str) -> Result<LinkAddress, String> {
        if let Some(rest) = text.strip_prefix("tcp:") {
            let (host, port) = rest.rsplit_once(':').ok_or_else(|| format!("`{text}`: expected tcp:HOST:PORT"))?;
            if host.is_empty() {
                return Err(format!("`{text}`: the host is empty (expected tcp:HOST:PORT)"));
            }
            let port: u16 = port.parse().map_err(|_| format!("`{text}`: the port `{port}` is not a number from 1 to 65535"))?;
            if port == 0 {
                return Err(format!("`{text}`: the port must be from 1 to 65535"));
            }
            // An IPv6 address is written in brackets in a URL; the socket wants it without.
            let host = host.strip_prefix('[').and_then(|h| h.strip_suffix(']')).unwrap_or(host);
            Ok(LinkAddress::Tcp { host: host.to_string(), port })
        } else if let Some(rest) = text.strip_prefix("serial:") {
            // A baud rate is the part after the last colon when it is one word of letters and
            // digits (or empty): a path may hold colons of its own, but then the part after
            // the last one has a dot, dash or slash
            // (`/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0`). A word that is not a
            // number is a bad baud rate, never part of the path (`serial:/dev/ttyS0:abc`).
            let (path, baud) = match rest.rsplit_once(':') {
                Some((path, baud)) if baud.bytes().all(|b| b.is_ascii_alphanumeric()) => {
                    if baud.is_empty() {
                        return Err(format!("`{text}`: the baud rate after the last `:` is empty (expected serial:PATH[:BAUD])"));
                    }
                    if !baud.bytes().all(|b| b.is_ascii_digit()) {
                        return Err(format!("`{text}`: the baud rate `{baud}` is not a number (expected serial:PATH[:BAUD], e.g. 115200)"));
                    }
                    let baud: u32 = baud.parse().map_err(|_| format!("`{text}`: the baud rate `{baud}` is too large"))?;
                    (path, baud)
                }
                _ => (rest, DEFAULT_BAUD),
            };
            if path.is_empty() {
                return Err(format!("`{text}`: the port is empty (expected serial:PATH[:BAUD], e.g. serial:/dev/ttyUSB0:115200)"));
            }
            if baud == 0 {
                return Err(format!("`{text}`: the baud rate must be above 0"));
            }
            Ok(LinkAddress::Serial { path: path.to_string(), baud })
        } else {
            Err(format!("`{text}`: expected tcp:HOST:PORT (the emulated board) or serial:PATH[:BAUD] (a board on a USB-UART adapter)"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tcp_and_serial_addresses_parse() {
        assert_eq!(LinkAddress::parse("tcp:127.0.0.1:5760"), Ok(LinkAddress::Tcp { host: "127.0.0.1".into(), port: 5760 }));
        assert_eq!(LinkAddress::parse("tcp:[::1]:5760"), Ok(LinkAddress::Tcp { host: "::1".into(), port: 5760 }));
        assert_eq!(LinkAddress::parse("serial:/dev/ttyUSB0"), Ok(LinkAddress::Serial { path: "/dev/ttyUSB0".into(), baud: 115_200 }));
        assert_eq!(LinkAddress::parse("serial:/dev/ttyUSB0:57600"), Ok(LinkAddress::Serial { path: "/dev/ttyUSB0".into(), baud: 57_600 }));
        let by_path = "serial:/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0";
        assert_eq!(
            LinkAddress::parse(by_path),
            Ok(LinkAddress::Serial { path: "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0".into(), baud: 115_200 })
        );
    }

    #[test]
    fn bad_addresses_say_what_is_wrong() {
        let err = |t: &str| LinkAddress::parse(t).unwrap_err();
        assert!(err("udp:1.2.3.4:5").contains("expected tcp:HOST:PORT"));
        assert!(err("tcp:localhost").contains("expected tcp:HOST:PORT"));
        assert!(err("tcp:localhost:http").contains("port `http`"));
        assert!(err("tcp:localhost:0").contains("1 to 65535"));
        assert!(err("tcp::5760").contains("host is empty"));
        assert!(err("serial:").contains("port is empty"));
        assert!(err("serial:/dev/ttyUSB0:0").contains("above 0"));
        assert!(err("serial:/dev/ttyUSB0:99999999999").contains("too large"));
        // A word after the last colon is a baud rate, not part of the path.
        assert!(err("serial:/dev/ttyS0:abc").contains("baud rate `abc` is not a number"), "{}", err("serial:/dev/ttyS0:abc"));
        assert!(err("serial:COM3:115k").contains("baud rate `115k`"));
        assert!(err("serial:/dev/ttyS0:").contains("baud rate after the last `:` is empty"));
    }
}
