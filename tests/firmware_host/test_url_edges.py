"""Edge cases of the udp:// and serial:// URLs, for the sinks and for ``ghnerf-listen``: a mistake is refused,
named, never taken as something else (a relative path, a random port, one of two bauds) or ignored."""
from __future__ import annotations

import re
from urllib.parse import urlsplit

import pytest

from drivers.url import redact_url
from firmware_host import listen
from firmware_host.errors import SinkConfigError
from firmware_host.sinks import open_sink
from firmware_host.sinks.serial_sink import SerialSink
from firmware_host.sinks.url import host_port, location_host, parse_url


def _refused(url: str) -> SinkConfigError:
    """The SinkConfigError ``open_sink(url)`` raises; a sink that opens instead is closed (no thread left behind)."""
    try:
        sink = open_sink(url)
    except SinkConfigError as e:
        return e
    sink.close(0.5)
    pytest.fail(f"{url} was accepted")


def _listen_fails(capsys, *argv: str) -> str:
    assert listen.main(list(argv)) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ghnerf-listen: error: ") and "\n" not in err and "Traceback" not in err
    return err


@pytest.mark.parametrize("url, message", [
    ("", "the URL is empty: give udp://[HOST]:PORT"),  # was ": the listener reads udp:// or serial://"
    ("udp://[::1:9871", "cannot be parsed"),  # an unclosed [: was a ValueError traceback, exit 1
    ("udp://:0", "bad port 0"),  # was bound to a port nobody was told, exit 0
    ("udp://127.0.0.1:0", "bad port 0"),
    ("serial:///dev/null?baud=9600&baud=921600", "baud given more than once"),  # was the first, quietly
    ("serial://dev/ttyUSB0?baud=9600", "serial:///dev/ttyUSB0"),  # was the relative path dev/ttyUSB0
    ("serial:dev/ttyUSB0", "serial:///dev/ttyUSB0"),
    ("udp://::1:9870", "brackets, e.g. udp://[::1]:9870"),
    ("udp://:9870/extra/path", "no path"),
    ("udp://user:pw@127.0.0.1:9870", "no user info"),
    ("serial://user:pw@dev/ttyUSB0", "serial:///user:***@dev/ttyUSB0"),
    ("udp://127.0.0.1:9870?token=pw", "unknown parameter token; it takes none"),
])
def test_listen_refuses_a_bad_url_in_one_line_exit_2(url, message, capsys):
    """The URL is named, as the sinks name theirs: without its password (``redact_url``; it was shown as given,
    ``pw`` and all, in a terminal's scrollback or a shell's log)."""
    err = _listen_fails(capsys, url, "--seconds", "0.1")
    assert redact_url(url) in err and message in err
    assert ":pw@" not in err and "=pw" not in err


def test_listen_shows_the_user_but_not_the_password():
    with pytest.raises(listen.ListenError) as refused:
        listen.open_port("udp://viewer:hunter2@127.0.0.1:9870")
    assert str(refused.value) == ("udp://viewer:***@127.0.0.1:9870: udp:// takes no user info (the part before '@') "
                                  "('viewer:***')")


def test_listen_api_takes_port_0_only_when_asked():
    with pytest.raises(listen.ListenError, match="bad port 0"):
        listen.open_port("udp://127.0.0.1:0")
    port = listen.open_port("udp://127.0.0.1:0/", ephemeral=True)  # a trailing / is no path
    try:
        assert port.address[1] > 0
    finally:
        port.close()


def test_listen_decodes_an_ipv6_zone():
    url = "udp://[fe80::1%25Eth0]:9870"
    # the listener and the sinks read the location through one function
    assert location_host(urlsplit(url), "udp") == "fe80::1%Eth0"  # decoded; the interface name keeps its case
    assert location_host(urlsplit("udp://[::1]:1"), "udp") == "::1"
    assert location_host(urlsplit("udp://:1"), "udp") == ""


@pytest.mark.parametrize("seconds", ["-1", "0", "nan", "inf", "-inf", "soon"])
def test_listen_seconds_must_be_positive_and_finite(seconds, capsys):
    with pytest.raises(SystemExit) as exit_:
        listen.main(["udp://127.0.0.1:9", f"--seconds={seconds}"])  # = : argparse takes -inf for an option
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "--seconds" in err and "finite number of seconds > 0" in err


@pytest.mark.parametrize("url", ["serial://dev/ttyACM0", "serial://dev/ttyACM0?baud=921600", "serial:dev/ttyACM0",
                                 "serial://localhost/dev/ttyACM0"])
def test_serial_sink_refuses_a_relative_or_hosted_device(url):
    e = _refused(url)
    assert e.field == "port" and e.url == url and "absolute path" in str(e) and "serial:///" in str(e)


def test_serial_sink_still_takes_an_absolute_path():
    assert SerialSink.from_url("serial:///dev/ttyACM0?baud=921600").port == "/dev/ttyACM0"
    assert SerialSink.from_url("serial:/dev/ttyACM0").port == "/dev/ttyACM0"


@pytest.mark.parametrize("url, field, value", [
    ("udp://127.0.0.1:9000/extra/path", "path", "/extra/path"),
    ("udp://user:pw@127.0.0.1:9000", "user info", "user:pw"),
    ("udp://user@127.0.0.1:9000", "user info", "user"),
    ("vmc://127.0.0.1:39539/x", "path", "/x"),
    ("vmc://me@127.0.0.1", "user info", "me"),
])
def test_udp_and_vmc_refuse_what_they_would_ignore(url, field, value):
    e = _refused(url)
    assert (e.field, e.value, e.url) == (field, value, url)


def test_an_unbracketed_ipv6_address_gets_a_hint():
    assert "missing host; an IPv6 address goes in brackets, e.g. udp://[::1]:9000" in str(_refused("udp://::1:9000"))
    assert "in brackets, e.g. vmc://[::1]" in str(_refused("vmc://::1"))
    plain = str(_refused("udp://:9000"))
    assert "missing host" in plain and "brackets" not in plain


@pytest.mark.parametrize("url, field, value, says", [
    # the listener's form (every interface) copied into a sink: said what a sink takes (the value was ':9870')
    ("udp://:9870", "host", "", "missing host; a sink sends to one receiver, e.g. udp://127.0.0.1:9870 "
                                "(udp://:PORT, every interface, is how ghnerf-listen listens)"),
    ("vmc://:39539", "host", "", "missing host; a sink sends to one receiver, e.g. vmc://127.0.0.1:39539"),
    # the port as written, not the whole location ('127.0.0.1:98700', '127.0.0.1')
    ("udp://127.0.0.1:98700", "port", "98700", "out of range"),
    ("udp://[::1]:99999", "port", "99999", "out of range"),
    ("vmc://robot.local:x", "port", "x", "integer"),
    ("udp://127.0.0.1", "port", "", "missing port: write udp://127.0.0.1:PORT, the receiver's"),
    ("udp://127.0.0.1:", "port", "", "missing port: write udp://127.0.0.1:PORT, the receiver's"),
])
def test_a_missing_or_bad_host_or_port_names_what_was_written_and_what_to_write(url, field, value, says):
    e = _refused(url)
    assert (e.field, e.value) == (field, value)
    assert says in str(e) and f"invalid {field}={value!r}" in str(e)


@pytest.mark.parametrize("url, example", [
    ("vmc://", "vmc://127.0.0.1:39539"),  # VMC's port, not the joint stream's 9870
    ("vmc://:", "vmc://127.0.0.1:39539"),
    ("udp://:abc", "udp://127.0.0.1:9870"),  # not a port: the example was udp://127.0.0.1:abc
    ("udp://:98700", "udp://127.0.0.1:9870"),  # out of range: the example was udp://127.0.0.1:98700
    ("udp://:9871", "udp://127.0.0.1:9871"),  # the port as written, where it is one
])
def test_a_missing_host_s_example_is_a_url_the_sink_takes(url, example):
    e = _refused(url)
    assert (e.field, e.value) == ("host", "")
    assert re.search(rf"a sink sends to one receiver, e\.g\. {re.escape(example)}( |$)", str(e)), str(e)
    open_sink(example).close(0.5)  # a URL the sink takes (UDP: nothing need listen)


def test_host_port_decodes_a_zone_and_takes_a_trailing_slash():
    assert host_port(parse_url("udp://[fe80::1%25Eth0]:9000")) == ("fe80::1%Eth0", 9000)
    assert host_port(parse_url("udp://[::1]:9000")) == ("::1", 9000)
    assert host_port(parse_url("udp://Example.COM:9000/")) == ("example.com", 9000)
    assert host_port(parse_url("vmc://127.0.0.1"), 39539) == ("127.0.0.1", 39539)


def test_keyword_none_is_not_given_and_true_is_no_number():
    # ep=None passed every check and retried forever; ep=True was endpoint 1
    from firmware_host.sinks.url import positive_int

    u = parse_url("usb://1209:0001?timeout_ms=250")
    assert u.take("timeout_ms", positive_int, 100, {"timeout_ms": None}) == 250  # the query's value stays
    assert parse_url("usb://1209:0001").take("timeout_ms", positive_int, 100, {"timeout_ms": None}) == 100
    with pytest.raises(SinkConfigError, match="timeout_ms.*not true/false"):
        parse_url("usb://1209:0001").take("timeout_ms", positive_int, 100, {"timeout_ms": True})


def test_a_usb_sink_without_an_endpoint_is_refused_at_once():
    from firmware_host.sinks.usb_sink import UsbSink

    with pytest.raises(SinkConfigError, match="ep.*the bulk OUT endpoint is required"):
        UsbSink.from_url("usb://1209:0001", ep=None)


def test_a_plus_in_a_sink_option_is_a_plus():
    """As in rig URLs: '+' in an option value is a plus, a space is %20."""
    from firmware_host.sinks.url import parse_url

    assert parse_url("udp://127.0.0.1:9000?name=a+b&x=c%20d").query == {"name": "a+b", "x": "c d"}


@pytest.mark.parametrize("url, field", [
    # termios takes a custom rate as a signed 32-bit int: this one failed every open (OverflowError,
    # logged as a backend bug) and was retried forever, after --validate-config had passed it
    ("serial:///dev/ttyACM0?baud=2147483648", "baud"),
    ("serial:///dev/ttyACM0?baud=9", "baud"),  # below B50: a frame every few minutes
    # past select()'s range: every frame of a stalled port failed with a traceback in the journal
    ("serial:///dev/ttyACM0?write_timeout_ms=10000000000000", "write_timeout_ms"),
    ("serial:///dev/ttyACM0?write_timeout_ms=60001", "write_timeout_ms"),
    # libusb's timeout is an unsigned 32-bit int where 0 means never: 2**32 wrapped to a write that never timed out
    ("usb://1209:0001?ep=0x01&timeout_ms=4294967296", "timeout_ms"),
])
def test_serial_and_usb_numbers_out_of_range_are_refused_up_front(url, field):
    e = _refused(url)
    assert e.field == field and e.url == url and "must be in [" in str(e)


def test_serial_and_usb_numbers_at_their_bounds_are_taken():
    from firmware_host.sinks.usb_sink import UsbSink

    sink = SerialSink.from_url("serial:///dev/ttyACM0?baud=2147483647&write_timeout_ms=60000")
    assert (sink.baud, sink.write_timeout_s) == (2**31 - 1, 60.0)
    assert SerialSink.from_url("serial:///dev/ttyACM0?baud=50").baud == 50
    assert UsbSink.from_url("usb://1209:0001?ep=0x01&timeout_ms=60000").timeout_ms == 60000


def test_serial_device_path_is_percent_decoded_as_the_docs_say():
    # docs/protocol.md: a '#' in a path is written %23; the serial sink opened the literal ".../a%23b"
    # (no such file, retried forever) where file:// and rig URLs decode it
    url = "serial:///dev/serial/by-id/usb-Board%231-if00?baud=921600"
    assert SerialSink.from_url(url).port == "/dev/serial/by-id/usb-Board#1-if00"


@pytest.mark.parametrize("url, host", [
    # getaddrinfo's IDNA codec raised UnicodeError on each: every connect failed, for ever, the first logged as a
    # backend bug with its traceback ("connect failed unexpectedly"), after --validate-config had passed the URL
    ("udp://robot..local:5005", "robot..local"),  # an empty label
    ("udp://" + "r" * 64 + ".local:5005", "r" * 64 + ".local"),  # a label past 63 characters
    ("vmc://%E2%80%8B:39539", "\u200b"),  # a zero-width space pasted with the name
    # never a name that resolves: each retried for ever as "not known"
    ("udp://robot%20one:5005", "robot one"),
    ("vmc://robot%00x:39539", "robot\x00x"),
    ("udp://" + "a." * 127 + "ab:5005", "a." * 127 + "ab"),  # 256 characters, past DNS's 253
])
def test_udp_and_vmc_refuse_a_host_that_can_never_be_looked_up(url, host):
    e = _refused(url)
    assert (e.field, e.value, e.url) == ("host", host, url)
    assert "host name" in str(e)


@pytest.mark.parametrize("url, host, says", [
    # getaddrinfo read these the C library's old way: the frames went to another address, without a word
    ("udp://192.168.001.010:5005", "192.168.001.010", "would be read as 192.168.1.8"),
    ("vmc://10.1:39539", "10.1", "would be read as 10.0.0.1"),
    # no name ends in an all-digit label: retried for ever as "Name or service not known"
    ("udp://192.168.1.300:5005", "192.168.1.300", "not an IPv4 address (four numbers 0 to 255) nor a host name"),
    ("udp://1.2.3.4.5:5005", "1.2.3.4.5", "not an IPv4 address"),
])
def test_udp_and_vmc_refuse_a_number_that_is_no_dotted_quad(url, host, says):
    e = _refused(url)
    assert (e.field, e.value, e.url) == ("host", host, url)
    assert says in str(e)


def test_listen_refuses_a_number_that_is_no_dotted_quad(capsys):
    err = _listen_fails(capsys, "udp://239.255.000.001:9870", "--seconds", "0.1")
    assert "bad host '239.255.000.001'" in err and "would be read as 239.255.0.1" in err


@pytest.mark.parametrize("host", ["robot.local", "robot.local.", "été.local", "host1.lan", "10.0.0.1", "::1", "a." * 126 + "a", "127.0.0.1",
                                  "fe80::1%Eth0", "r" * 63])
def test_host_names_dns_can_carry_are_taken(host):
    from firmware_host.sinks.url import host_name_problem

    assert host_name_problem(host) == ""


def test_listen_refuses_a_host_that_can_never_be_looked_up_in_the_sinks_words(capsys):
    # was "cannot listen: encoding with 'idna' codec failed (UnicodeError: label empty or too long)"
    err = _listen_fails(capsys, "udp://robot..local:9870", "--seconds", "0.1")
    assert "bad host 'robot..local'" in err and "each dot-separated label is 1 to 63 characters" in err


def test_listen_reads_a_baud_as_the_serial_sink_does(capsys):
    url = "serial:///dev/ttyACM0?baud=0x1C200"  # hex, as a sink URL may write it: was "baud must be a whole number"
    assert SerialSink.from_url(url).baud == 115200
    assert "baud must be" not in _listen_fails(capsys, url.replace("/dev/ttyACM0", "/dev/nonexistent-ghnerf"),
                                               "--seconds", "0.1")
    # a leading zero, refused by the sink (C reads 010 as octal 8), was taken as decimal 9600
    err = _listen_fails(capsys, "serial:///dev/null?baud=09600", "--seconds", "0.1")
    assert "baud must be a whole number: decimal digits expected, without a leading zero" in err


@pytest.mark.parametrize("raw, says", [
    ("9_600", "without '_'"),  # Python's int() read 9600 at both ends
    ("%209600", "without spaces"),
    ("%2B9600", "without a sign: no whole-number option is negative (write 9600)"),
    ("+9600", "without a sign: no whole-number option is negative (write 9600)"),  # '+' is a plus, as in sink URLs
])
def test_listen_and_the_serial_sink_refuse_a_baud_that_is_not_plain_digits(capsys, raw, says):
    err = _listen_fails(capsys, f"serial:///dev/null?baud={raw}", "--seconds", "0.1")
    assert "baud must be a whole number: " in err and says in err
    e = _refused(f"serial:///dev/ttyACM0?baud={raw}")
    assert e.field == "baud" and says in str(e)


@pytest.mark.parametrize(("url", "said"), [
    # decoded to U+FFFD, the sink wrote (or opened, or looked up) another name than the one given
    ("file:///tmp/joints%FF.jsonl", "invalid path='/tmp/joints%FF.jsonl': holds %FF, which is not UTF-8"),
    ("serial:///dev/serial/by-id/usb-%FE", "invalid port='/dev/serial/by-id/usb-%FE': holds %FE, which is not UTF-8"),
    ("udp://host%FF:9870", "invalid host='host%FF': holds %FF, which is not UTF-8"),
    ("file:///tmp/joints.jsonl?queue=8%FF", "invalid queue='8%FF': holds %FF, which is not UTF-8"),
])
def test_a_sink_url_escape_of_a_byte_that_is_not_utf8_is_refused_naming_the_part(url, said, tmp_path):
    e = _refused(url)
    assert said in str(e) and "(give the path in UTF-8, or rename the file)" in str(e)


def test_listen_and_the_serial_sink_refuse_a_device_no_file_can_be(capsys):
    """A NUL reached pyserial: its ValueError was "cannot open" (the sink retried it for ever)."""
    url = "serial:///dev/tty%00"
    assert "the device '/dev/tty\\x00': holds a NUL byte" in _listen_fails(capsys, url, "--seconds", "0.1")
    e = _refused(url)
    assert e.field == "port" and "holds a NUL byte" in str(e)


def test_a_file_sink_path_of_utf8_escapes_is_decoded(tmp_path):
    sink = open_sink(f"file://{tmp_path}/t%C3%A9.jsonl")
    sink.close(0.5)
    assert sink.path == f"{tmp_path}/t\u00e9.jsonl"
