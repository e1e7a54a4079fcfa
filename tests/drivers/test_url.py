"""RigUrl: typed options, defaults, range checks, unknown options rejected by name."""
import pytest

from drivers import RigConfigError, create_rig_source
from drivers.url import RigUrl, UrlPartError, decode_url_part, redact_url


def test_parse_scheme_target_and_options():
    url = RigUrl.parse("Replay:///data/take%201?speed=free&loop=1")
    assert url.scheme == "replay"
    assert url.target == "/data/take 1"
    assert url.options == {"speed": "free", "loop": "1"}


def test_typed_getters_convert_and_consume():
    url = RigUrl.parse("sim://?fps=60&seed=0x10&noise=2.5&cache=off&on=yes&off=0&flag")
    assert url.take_float("fps", 30.0) == 60.0
    assert url.take_int("seed", 0) == 16
    assert url.take_float("noise", 0.0, lo=0.0) == 2.5
    assert url.take_str("cache", "auto") == "off"
    assert url.take_bool("on", False) is True
    assert url.take_bool("off", True) is False
    assert url.take_bool("flag", False) is True  # bare key means true
    assert url.take_float("absent", 1.5) == 1.5  # defaults when missing
    url.finish()  # everything was consumed


def test_prefixed_bases_are_whole_numbers():
    url = RigUrl.parse("sim://?a=0x10&b=0o17&c=0b101&d=0&e=00&f=0X1f")
    assert [url.take_int(k, -1) for k in "abcdef"] == [16, 15, 5, 0, 0, 31]


@pytest.mark.parametrize(("raw", "says"), [
    # Python's int() took all of these: queue=%205 read 5, seed=1_0 read 10, other scripts' digits their value
    ("%205", "without spaces"),
    ("5%20", "without spaces"),
    ("1_0", "without '_'"),
    ("0x_1f", "without '_'"),
    ("%D9%A1%D9%A2", "ASCII digits 0-9 expected, not '\u0661'"),  # Arabic-Indic 12
    ("%EF%BC%91", "ASCII digits 0-9 expected"),  # fullwidth 1
    ("%2B5", "without a sign: no whole-number option is negative (write 5)"),
    ("-7", "without a sign: no whole-number option is negative"),
])
def test_a_whole_number_is_ascii_digits_only(raw, says):
    """The docs say decimal digits (or a 0x/0o/0b prefix): spaces, '_', a sign and other digits are refused by
    name in rig and sink URLs alike, not read as a number."""
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks import open_sink

    with pytest.raises(RigConfigError) as rig:
        RigUrl.parse(f"sim://?seed={raw}").take_int("seed", 0)
    with pytest.raises(SinkConfigError) as sink:
        open_sink(f"memory://?queue={raw}")
    assert "option seed=" in str(rig.value) and says in str(rig.value)
    assert sink.value.field == "queue" and says in str(sink.value)


@pytest.mark.parametrize(("raw", "says"), [
    ("3_0", "must be a number, without '_'"),  # a typo for 3.0 ran at 30
    ("%2030", "must be a number, without spaces"),
    ("30%20", "without spaces"),
    ("%D9%A3", "must be a number in ASCII digits 0-9 (not '\u0663')"),
    ("nan", "must be a finite number"),
    ("-inf", "must be a finite number"),
    ("0x1e", "must be a number: digits, with one '.'"),
])
def test_a_number_with_a_fraction_is_a_plain_ascii_decimal(raw, says):
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks import open_sink

    with pytest.raises(RigConfigError) as rig:
        RigUrl.parse(f"sim://?fps={raw}").take_float("fps", 30.0)
    with pytest.raises(SinkConfigError) as sink:
        open_sink(f"memory://?fps={raw}")
    assert "option fps=" in str(rig.value) and says in str(rig.value)
    assert sink.value.field == "fps" and says in str(sink.value)
    with pytest.raises(RigConfigError) as speed:  # replay's speed= reads a number the same way
        create_rig_source(f"replay:///nonexistent?speed={raw}")
    assert "option speed=" in str(speed.value) and says in str(speed.value)


def test_decimals_as_strtod_writes_them_are_taken():
    url = RigUrl.parse("sim://?a=1e-3&b=%2B2.5&c=-1.5E%2B2&d=5.&e=.5")
    assert [url.take_float(k, 0.0) for k in "abcde"] == [1e-3, 2.5, -150.0, 5.0, 0.5]


def test_a_yes_no_word_takes_any_case_but_no_spaces():
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks import open_sink

    url = RigUrl.parse("sim://?a=Yes&b=OFF")
    assert (url.take_bool("a", False), url.take_bool("b", True)) == (True, False)
    for raw in ("%20yes", "yes%20", "%EF%BD%99es"):  # a space around it (was yes in sink URLs); a fullwidth y
        with pytest.raises(RigConfigError, match="option loop="):
            RigUrl.parse(f"sim://?loop={raw}").take_bool("loop", False)
        with pytest.raises(SinkConfigError) as sink:
            open_sink(f"memory://?send_2d={raw}")
        assert sink.value.field == "send_2d" and "yes/no" in str(sink.value)


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("sim://?seed=010",
         "option seed='010': decimal digits expected, without a leading zero (write 10; hex as 0x..)"),
        ("sim://?width=0640", "option width='0640': decimal digits expected, without a leading zero (write 640;"),
        ("record+sim://?out=/tmp/x&writers=02", "option writers='02': decimal digits expected"),
        ("depthai://?queue=08", "option queue='08': decimal digits expected, without a leading zero (write 8;"),
        ("opencv://?first=0&second=1&queue=04", "option queue='04': decimal digits expected"),
    ],
)
def test_an_integer_with_a_leading_zero_is_refused_as_sink_urls_refuse_it(url, says):
    """seed=010 read as 10 here, while a sink URL refused queue=010 (C reads 010 as octal 8; a user who typed 08
    meant something): one rule for both, refused before anything opens, naming the option and the value."""
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    assert says in str(info.value) and url.split("?")[1] in str(info.value)  # record+ names its inner URL


def test_camera_and_sink_urls_give_one_reason_for_a_leading_zero():
    from firmware_host.errors import SinkConfigError
    from firmware_host.sinks import open_sink

    for raw, write in (("010", "write 10;"), ("-025", "without a sign"), ("+08", "without a sign: no whole-number "
                                                                            "option is negative (write 8)")):
        with pytest.raises(RigConfigError) as rig:
            RigUrl.parse(f"sim://?offset={raw.replace('+', '%2B')}").take_int("offset", 0)
        with pytest.raises(SinkConfigError) as sink:
            open_sink(f"memory://?queue={raw.replace('+', '%2B')}")
        rig_reason = str(rig.value).split(f"offset={raw!r}: ")[1]
        sink_reason = str(sink.value).split(f"queue={raw!r}: ")[1]
        assert rig_reason == sink_reason and write in rig_reason


def test_a_number_with_a_fraction_reads_a_leading_zero_as_decimal():
    """Floats are not ambiguous (C's strtod reads 08.5 and 010 as decimal), as in sink URLs."""
    url = RigUrl.parse("sim://?fps=030&noise=01.5&offset_ms=-010&drop=.05")
    assert url.take_float("fps", 0.0) == 30.0
    assert url.take_float("noise", 0.0) == 1.5
    assert url.take_float("offset_ms", 0.0, lo=-1000.0) == -10.0
    assert url.take_float("drop", 0.0) == 0.05


@pytest.mark.parametrize(
    ("query", "getter", "expected_words"),
    [
        ("fps=fast", lambda u: u.take_float("fps", 30.0), ["fps='fast'", "a number"]),
        ("fps=-1", lambda u: u.take_float("fps", 30.0, lo=0.0), ["fps='-1'", "[0.0, None]"]),
        ("fps=nan", lambda u: u.take_float("fps", 30.0), ["fps='nan'"]),
        ("fps=inf", lambda u: u.take_float("fps", 30.0, lo=0.0), ["fps='inf'"]),
        ("seed=1.5", lambda u: u.take_int("seed", 0), ["seed='1.5'", "expected a whole number"]),
        ("loop=maybe", lambda u: u.take_bool("loop", False), ["loop='maybe'", "boolean"]),
        ("policy=best", lambda u: u.take_str("policy", "latest", choices=("latest", "all")), ["policy='best'", "latest"]),
    ],
)
def test_bad_values_name_the_option_and_the_value(query, getter, expected_words):
    url = RigUrl.parse(f"sim://?{query}")
    with pytest.raises(RigConfigError) as info:
        getter(url)
    for word in expected_words:
        assert word in str(info.value)


def test_unknown_option_is_rejected_by_name():
    url = RigUrl.parse("sim://?fps=30&fsp=60")
    url.take_float("fps", 30.0)
    with pytest.raises(RigConfigError, match="fsp"):
        url.finish()


def test_duplicate_option_is_rejected():
    with pytest.raises(RigConfigError, match="fps"):
        RigUrl.parse("sim://?fps=30&fps=60")


@pytest.mark.parametrize("text", ["sim", "", "/data/take1", "sim://[::1?x"])
def test_not_a_url(text):
    with pytest.raises(RigConfigError):
        RigUrl.parse(text)


@pytest.mark.parametrize(
    ("url", "fragment"),
    [("record+sim://?out=/data/take#3", "'#3'"), ("replay:///data/run#2", "'#2'"), ("sim://?fps=30#", "'#'")],
)
def test_a_fragment_is_refused_not_dropped(url, fragment):
    """``#`` starts a fragment, which parsing would drop: another take played or recorded into."""
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    assert fragment in str(info.value) and "%23" in str(info.value)
    assert RigUrl.parse("replay:///data/run%232").target == "/data/run#2"  # the way to write one


@pytest.mark.parametrize(
    "url",
    ["sim://?fsp=60", "replay:///nonexistent?sped=free", "record+sim://?out=/tmp/x&bogus=1", "depthai://?widht=640"],
)
def test_every_backend_rejects_unknown_options_by_name(url):
    """Backends validate the URL before touching anything (no device, no files)."""
    name = {"sim": "fsp", "rep": "sped", "rec": "bogus", "dep": "widht"}[url[:3]]
    with pytest.raises(RigConfigError, match=name):
        create_rig_source(url)


def test_a_plus_in_an_option_is_a_plus_and_a_space_is_percent_20():
    """Query values read as the path does: '+' is a plus (a form's '+' for a space recorded out=/data/take+1 into
    '/data/take 1'); a space is written %20."""
    from drivers.url import RigUrl

    url = RigUrl.parse("record+sim://?out=/data/take+1&note=a%20b%2Bc")
    assert url.options == {"out": "/data/take+1", "note": "a b+c"}


# ----------------------------------------------------------------- passwords are never shown
STREAM = "opencv://?first=rtsp%3A%2F%2Fadmin%3Ahunter2%40cam1%2Fstream&second=%2Fdev%2Fvideo2"


@pytest.mark.parametrize(("url", "shown"), [
    ("rtsp://admin:hunter2@cam1:554/live?x=1", "rtsp://admin:***@cam1:554/live?x=1"),
    ("rtsp://admin:hun:ter@2@cam1/live", "rtsp://admin:***@cam1/live"),
    (STREAM, "opencv://?first=rtsp%3A%2F%2Fadmin%3A***%40cam1%2Fstream&second=%2Fdev%2Fvideo2"),
    ("opencv://?first=rtsp%3A%2F%2Fcam%2Fs%3Ftoken%3Dhunter2&second=0",
     "opencv://?first=rtsp%3A%2F%2Fcam%2Fs%3Ftoken%3D***&second=0"),
    ("http://cam/x?password=hunter2&Token=hunter2&api_key=hunter2&stream_secret=hunter2&fps=30",
     "http://cam/x?password=***&Token=***&api_key=***&stream_secret=***&fps=30"),
    ("record+opencv://?first=rtsp%3A%2F%2Fu%3Ahunter2%40h&second=0&out=/d",
     "record+opencv://?first=rtsp%3A%2F%2Fu%3A***%40h&second=0&out=/d"),
    ("x://u:hunter2@[::1/", "x://u:***@[::1/"),  # a host urlsplit cannot parse
    ("http://cam/x?api-key=hunter2&apikey=hunter2&AccessKey=hunter2&access_key=hunter2&keyframes=2",
     "http://cam/x?api-key=***&apikey=***&AccessKey=***&access_key=***&keyframes=2"),  # hyphenated too
])
def test_a_url_is_shown_without_its_passwords(url, shown):
    from drivers.url import redact_url

    assert redact_url(url) == shown


@pytest.mark.parametrize("url", ["sim://?fps=30&seed=3", "replay:///data/take 1", "rtsp://admin@cam1/live",
                                 "opencv://?first=%2Fdev%2Fvideo0&second=2&passes=3", "depthai://"])
def test_a_url_without_a_password_is_shown_as_written(url):
    from drivers.url import redact_url

    assert redact_url(url) == url


def test_a_parsed_rig_url_shows_no_password_but_keeps_it_to_open():
    url = RigUrl.parse(STREAM)
    assert "hunter2" not in url.url and "admin%3A***%40cam1" in url.url
    assert url.options["first"] == "rtsp://admin:hunter2@cam1/stream"
    with pytest.raises(RigConfigError) as info:
        RigUrl.parse(STREAM + "&fps=1&fps=2")
    assert "hunter2" not in str(info.value)


@pytest.mark.parametrize("option", ["rig", "cache", "out", "speed"])
def test_an_empty_text_option_is_refused_not_read_as_absent(option):
    # depthai://?rig= ran on the device's calibration and sim://?cache= on the default cache: the file or folder
    # meant (a variable left unset in a config) was never named, and nothing said so
    url = RigUrl.parse(f"sim://?fps=30&{option}=")
    with pytest.raises(RigConfigError) as info:
        url.take_str(option, "default")
    assert f"option {option}= is empty" in str(info.value) and "sim://?fps=30" in str(info.value)


def test_an_empty_rig_file_option_is_refused_by_the_backends():
    from drivers.backends.sim import SimOptions

    with pytest.raises(RigConfigError, match="option cache= is empty"):
        SimOptions.from_url(RigUrl.parse("sim://?cache="))
    depthai_options = pytest.importorskip("drivers.backends.depthai.options")
    with pytest.raises(RigConfigError, match="option rig= is empty"):
        depthai_options.DepthaiOptions.from_url(RigUrl.parse("depthai://?rig="))


@pytest.mark.parametrize(("url", "said"), [
    # unquote's default made each U+FFFD: "recording directory /take\ufffd does not exist", a name never given
    ("replay:///take%FF", "rig URL 'replay:///take%FF': the path after :// holds %FF, which is not UTF-8"),
    ("opencv://?first=%FF.mp4&second=b.mp4", "option first= holds %FF, which is not UTF-8"),
    ("opencv://?first=a.mp4&second=%C3%A9%FE%FF.mp4", "option second= holds %FE%FF, which is not UTF-8"),
    ("sim://?%FF=1", "an option name holds %FF, which is not UTF-8"),
])
def test_an_escape_of_a_byte_that_is_not_utf8_is_refused_naming_the_part(url, said):
    with pytest.raises(RigConfigError) as e:
        RigUrl.parse(url)
    assert said in str(e.value) and "(give the path in UTF-8, or rename the file)" in str(e.value)
    with pytest.raises(RigConfigError, match="which is not UTF-8"):
        create_rig_source(url)


def test_one_helper_decodes_a_url_part_and_refuses_escapes_that_are_not_utf8_naming_the_field():
    # the rule rig URLs, sink URLs and ghnerf-listen each wrote out (decode, then look for kept bytes): one place now
    assert decode_url_part("the device", "/dev/usb-Robot%231-t%C3%A9") == "/dev/usb-Robot#1-t\u00e9"
    with pytest.raises(UrlPartError) as e:
        decode_url_part("the device", "/dev/tty%C3%A9%FE")
    assert (e.value.field, e.value.value) == ("the device", "/dev/tty%C3%A9%FE")
    assert e.value.why.startswith("holds %FE, which is not UTF-8")
    assert str(e.value) == f"the device {e.value.why}" and isinstance(e.value, ValueError)


def test_escapes_of_utf8_text_are_decoded_as_before():
    url = RigUrl.parse("replay:///data/t%C3%A9?out=%E2%82%AC")
    assert url.target == "/data/t\u00e9" and url.options == {"out": "\u20ac"}


@pytest.mark.parametrize(("url", "said"), [
    # urlsplit removes a tab, CR or LF from anywhere in a URL: another take played, another rate run
    ("replay:///data/ta\tke?loop=1", "holds a tab at character 18, which URL parsing drops; remove it, or write "
                                     "it as %09"),
    ("sim://?fps=3\n0", "holds a line feed at character 13"),
    ("opencv://?first=a\r.mp4&second=b.mp4", "holds a carriage return at character 18"),
    ("sim://?fps=30\n", "holds a line feed at character 14"),
    ("record+sim://?out=/data/t\tx", "holds a tab at character"),
    # counted in the URL as shown: the password before it is *** there (it was counted in the URL as given)
    ("opencv://?first=rtsp%3A%2F%2Fa%3Ahunter2%40h%2Fs&second=x\t.mp4", "holds a tab at character 54,"),
    ("opencv://?first=a.mp4&second=b.mp4&password=hunt\ter2", "holds a tab, which URL parsing drops"),
])
def test_a_tab_or_line_break_that_url_parsing_drops_is_refused_naming_it(url, said):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    assert said in str(info.value)
    assert RigUrl.parse("replay:///data/ta%09ke").target == "/data/ta\tke"  # the way to write one


@pytest.mark.parametrize(("url", "said"), [
    # kept by urlsplit, they reached log lines raw: an ESC sequence rewrote the terminal (session 74)
    ("replay:///data/ta\x1b[2Jke", "'replay:///data/ta\\x1b[2Jke': holds a control character (U+001B) at character 18, "
                                   "which logs and terminals would act on or hide; remove it, or write it as %1B"),
    ("sim://?fps=3\x000", "holds a control character (U+0000) at character 13"),
    ("sim://?fps=30\x7f", "holds a control character (U+007F) at character 14"),
    ("replay:///data/\x85take", "'replay:///data/\\x85take': holds a control character (U+0085) at character 16, "
                                "which logs and terminals would act on or hide; remove it, or write it as %C2%85"),
    ("sim://?fps=30&seed=1\x0b", "(U+000B) at character 21"),
    ("sim://?fps=30\x0c", "(U+000C) at character 14"),
    ("\x01sim://?fps=30", "(U+0001) at character 1"),  # urlsplit strips a leading C0 control: refused as well
])
def test_every_other_control_character_is_refused_naming_its_code_point_and_place(url, said):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    assert said in str(info.value) and len(str(info.value).splitlines()) == 1, str(info.value)
    assert "\x1b" not in str(info.value)


@pytest.mark.parametrize(("url", "said"), [
    # no C0/C1 control, so taken before: a separator broke the line that showed the URL, a bidi control showed
    # its characters in another order than the one opened ("\u202elmth.take" showed as "ekat.html")
    ("replay:///data/ta\u2028ke", "'replay:///data/ta\\u2028ke': holds a line separator (U+2028) at character 18, "
                                   "which logs and editors break the line at; remove it, or write it as %E2%80%A8"),
    ("sim://?fps=30\u2029", "holds a paragraph separator (U+2029) at character 14"),
    ("replay:///data/\u202elmth.take", "'replay:///data/\\u202elmth.take': holds a bidirectional-text control "
                                       "(U+202E) at character 16, which makes logs and terminals show the characters "
                                       "after it in another order; remove it, or write it as %E2%80%AE"),
    *((f"replay:///data/t{chr(code)}ake", f"holds a bidirectional-text control (U+{code:04X}) at character 17")
      for code in (0x061C, 0x200E, 0x200F, 0x202A, 0x202B, 0x202C, 0x202D, 0x2066, 0x2067, 0x2068, 0x2069)),
])
def test_a_line_separator_or_bidi_control_is_refused_naming_its_code_point_and_place(url, said):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    assert said in str(info.value) and len(str(info.value).splitlines()) == 1, str(info.value)
    assert RigUrl.parse("replay:///data/t%E2%80%AEx").target == "/data/t\u202ex"  # written as an escape


def test_printable_text_that_is_not_ascii_is_still_taken():
    assert RigUrl.parse("replay:///data/caf\u00e9/\u6f14\u793a\u00a0x").target == "/data/caf\u00e9/\u6f14\u793a\u00a0x"
    assert RigUrl.parse("replay:///data/t%1Bx").target == "/data/t\x1bx"  # written as an escape, as a tab's %09 is


@pytest.mark.parametrize("url", [
    # urlsplit reads these as a password (it drops the tab, CR or LF), so their refusal must hide it too
    "rtsp:/\t/user:hunter2@cam/s",
    "rtsp:\r\n//user:hunter2@cam/s",
    "sim://?pass\tword=hunter2",
    "sim://?token\n=hunter2",
    "opencv://?first=rtsp:/\t/user:hunter2@cam&second=b.mp4",
])
def test_a_secret_that_url_parsing_reads_past_a_dropped_character_is_not_shown(url):
    with pytest.raises(RigConfigError) as info:
        create_rig_source(url)
    assert "hunter2" not in str(info.value), str(info.value)
    assert "hunter2" not in redact_url(url) and "***" in redact_url(url)


@pytest.mark.parametrize("url", ["sim:/\t/?fps=30", "rtsp:\r\n//user:hunter2@cam/s"])
def test_a_dropped_character_inside_the_scheme_separator_is_named(url):
    """urlsplit reads these as URLs (it drops the tab, CR or LF): named as the sinks and ghnerf-listen name it, not
    as a text without '://'."""
    with pytest.raises(RigConfigError, match="which URL parsing drops"):
        RigUrl.parse(url)
