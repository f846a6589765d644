"""Studies of the methods on a case: the method advisor (``advise``), the side-by-side comparison
of the paper's methods (``compare``), the verification against a tight reference
(``verification``) and the HTML report of one run (``report``). Nothing is imported here."""
