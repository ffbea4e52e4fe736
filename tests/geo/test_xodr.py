"""twinkit.geo.xodr: an OpenDRIVE document under a similarity (the options road_source=opendrive adds:
translation, heights unscaled, a vertical offset, the identity kept as written). The CARLA package's use
(heights scaled, no translation) is tested in plugins/twinkit-export/tests/test_carla_frame.py."""
import math
import xml.etree.ElementTree as ET

import pytest

from twinkit.geo.xodr import XodrFrameError, transform_xodr

DOC = """<?xml version="1.0"?>
<OpenDRIVE><header revMajor="1" revMinor="4" north="10" south="-10" east="100" west="0">
<geoReference><![CDATA[+proj=tmerc +lat_0=0 +lon_0=0]]></geoReference></header>
<road length="100" id="1" junction="-1"><planView>
<geometry s="0" x="1.5e+0" y="2.0" hdg="0.1" length="100"><arc curvature="0.01"/></geometry></planView>
<elevationProfile><elevation s="0" a="2" b="0.1" c="0.01" d="0.001"/></elevationProfile>
<lateralProfile><superelevation s="0" a="0.02" b="0.001" c="0" d="0"/></lateralProfile>
<lanes><laneSection s="10"><right><lane id="-1" type="driving">
<width sOffset="5" a="3.5" b="0.1" c="0.01" d="0.001"/><height sOffset="0" inner="0.1" outer="0.2"/></lane></right>
</laneSection></lanes>
<objects><object id="o" s="20" t="3" zOffset="0.5" height="2" width="1" length="1" hdg="0"/></objects>
</road></OpenDRIVE>"""


def attrs(text, tag):
    return ET.fromstring(text.encode()).find(f".//{tag}").attrib


def test_translation_and_unscaled_heights():
    k, th = 1.01, math.radians(3.0)
    out = transform_xodr(DOC, th, k, "+proj=utm +zone=35", translation=(100.0, -50.0), scale_heights=False,
                         dz=-12.0)
    g = attrs(out, "geometry")
    x = k * (math.cos(th) * 1.5 - math.sin(th) * 2.0) + 100.0
    y = k * (math.sin(th) * 1.5 + math.cos(th) * 2.0) - 50.0
    assert float(g["x"]) == pytest.approx(x) and float(g["y"]) == pytest.approx(y)
    assert float(g["hdg"]) == pytest.approx(0.1 + th) and float(g["length"]) == pytest.approx(100 * k)
    assert float(attrs(out, "arc")["curvature"]) == pytest.approx(0.01 / k)
    e = attrs(out, "elevation")  # a height: value kept (+ dz), coefficients per length
    assert [float(e[c]) for c in "abcd"] == pytest.approx([2 - 12.0, 0.1 / k, 0.01 / k ** 2, 0.001 / k ** 3])
    w = attrs(out, "width")  # a length: a * k, b, c / k, d / k^2
    assert [float(w[c]) for c in "abcd"] == pytest.approx([3.5 * k, 0.1, 0.01 / k, 0.001 / k ** 2])
    assert float(w["sOffset"]) == pytest.approx(5 * k)
    h = attrs(out, "height")
    assert (float(h["inner"]), float(h["outer"])) == (0.1, 0.2)
    o = attrs(out, "object")
    assert (float(o["s"]), float(o["t"])) == pytest.approx((20 * k, 3 * k))
    assert (float(o["zOffset"]), float(o["height"])) == (0.5, 2.0)
    assert ET.fromstring(out.encode()).find("header/geoReference").text == "+proj=utm +zone=35"


def test_heights_scale_for_the_carla_package():
    out = transform_xodr(DOC, 0.2, 1.01)
    assert float(attrs(out, "elevation")["a"]) == pytest.approx(2 * 1.01)
    assert float(attrs(out, "object")["height"]) == pytest.approx(2 * 1.01)


def test_identity_keeps_every_digit():
    out = transform_xodr(DOC, 0.0, 1.0, "+proj=x", dz=1.0)
    g = attrs(out, "geometry")
    assert g["x"] == "1.5e+0" and g["y"] == "2.0" and g["hdg"] == "0.1"
    assert float(attrs(out, "elevation")["a"]) == 3.0
    assert attrs(out, "header")["east"] == "100"


def test_unknown_length_attributes_stop_a_scaled_move():
    bad = DOC.replace("<objects>", '<mystery s="3" length="4"/><objects>')
    with pytest.raises(XodrFrameError, match="mystery"):
        transform_xodr(bad, 0.0, 1.01, scale_heights=False)


def test_twinkits_header_tags_are_read_in_both_spellings():
    """from_scan / has_no_roads read road_source=scan's header tags as written, and after an XML round trip
    (ElementTree writes ``value="scan" />``); a map without them is neither."""
    import xml.etree.ElementTree as ET

    from twinkit.geo.xodr import NO_ROADS_TAG, SCAN_TAG, from_scan, has_no_roads

    text = f'<?xml version="1.0"?>\n<OpenDRIVE><header revMajor="1" revMinor="4">{SCAN_TAG}{NO_ROADS_TAG}</header></OpenDRIVE>'
    again = ET.tostring(ET.fromstring(text.split("\n", 1)[1]), encoding="unicode")
    assert 'value="scan" />' in again
    for t in (text, again):
        assert from_scan(t) and has_no_roads(t)
    plain = '<OpenDRIVE><header revMajor="1" revMinor="4"><userData code="other" value="scan"/></header></OpenDRIVE>'
    assert not from_scan(plain) and not has_no_roads(plain)
    assert from_scan(text.replace(NO_ROADS_TAG, "")) and not has_no_roads(text.replace(NO_ROADS_TAG, ""))
