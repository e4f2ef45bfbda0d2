"""User text in leaderboard.md / leaderboard.csv cannot become a link, an image or a spreadsheet formula."""

from simspad.evaluate.leaderboard.markdown_page import md_escape
from simspad.evaluate.leaderboard.tables import csv_safe


def test_markdown_syntax_in_user_text_is_shown_as_written():
    out = md_escape("[click](http://evil) ![x](y) <script> a|b *c* `d`")
    # Every "[" and "]" is backslash-escaped, so no link or image can form; HTML is entity-escaped.
    assert out == r"\[click\](http://evil) !\[x\](y) &lt;script&gt; a\|b \*c\* \`d\`"
    assert md_escape("NI (S)") == "NI (S)"


def test_spreadsheet_formulas_are_neutralised_numbers_are_not():
    assert csv_safe('=HYPERLINK("http://evil","x")') == '\'=HYPERLINK("http://evil","x")'
    assert [csv_safe(v) for v in ("+1", "-cmd", "@SUM(A1)", "ni", 3.5, -2.0)] == ["'+1", "'-cmd", "'@SUM(A1)", "ni",
                                                                                   3.5, -2.0]
