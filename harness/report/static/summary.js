/* The suite report's summary table: filters (All / Failures / Errors / Unexpected) and sorting by any column.
   Included inline by suite.html.j2; the table is plain HTML and reads the same without it.
   Rows: tr[data-status] ("pass" | "fail" | "error") and tr[data-ok] ("true" | "false"; unexpected = ok is false).
   Cells: td[data-sort] holds the value a column sorts by (numbers as plain decimals, "" for none);
   th[data-sort-type="number"] sorts numerically (none last), others as text. */
(function () {
  "use strict";
  var table = document.querySelector("table.summary");
  var bar = document.querySelector("[data-filters]");
  if (!table || !table.tBodies.length) { return; }
  var body = table.tBodies[0];
  var rows = Array.prototype.slice.call(body.rows);
  var tests = {
    all: function () { return true; },
    failures: function (row) { return row.getAttribute("data-status") === "fail"; },
    errors: function (row) { return row.getAttribute("data-status") === "error"; },
    unexpected: function (row) { return row.getAttribute("data-ok") === "false"; }
  };

  function filter(name) {
    var test = tests[name] || tests.all, shown = 0;
    rows.forEach(function (row) {
      var keep = test(row);
      row.hidden = !keep;
      shown += keep ? 1 : 0;
    });
    if (bar) {
      Array.prototype.forEach.call(bar.querySelectorAll("[data-filter]"), function (button) {
        button.setAttribute("aria-pressed", String(button.getAttribute("data-filter") === name));
      });
      var count = bar.querySelector("[data-shown]");
      if (count) { count.textContent = shown + " of " + rows.length + " cases shown"; }
    }
    table.setAttribute("data-filtered", name);
  }

  if (bar) {
    bar.hidden = false;
    Array.prototype.forEach.call(bar.querySelectorAll("[data-filter]"), function (button) {
      var name = button.getAttribute("data-filter");
      var n = rows.filter(tests[name] || tests.all).length;
      var label = button.querySelector("[data-count]");
      if (label) { label.textContent = String(n); }
      button.addEventListener("click", function () { filter(name); });
    });
  }

  function key(row, column) {
    var cell = row.cells[column];
    if (!cell) { return ""; }
    var value = cell.getAttribute("data-sort");
    return value === null ? cell.textContent.trim() : value;
  }

  var headers = Array.prototype.slice.call(table.tHead ? table.tHead.rows[0].cells : []);
  headers.forEach(function (th, column) {
    var numeric = th.getAttribute("data-sort-type") === "number";
    th.setAttribute("tabindex", "0");
    th.setAttribute("aria-sort", "none");
    th.style.cursor = "pointer";
    th.title = "sort by this column (again: reverse)";
    function sort() {
      var ascending = th.getAttribute("aria-sort") !== "ascending";
      headers.forEach(function (other) { other.setAttribute("aria-sort", "none"); });
      th.setAttribute("aria-sort", ascending ? "ascending" : "descending");
      var order = rows.map(function (row, index) { return [row, index]; });
      order.sort(function (a, b) {
        var x = key(a[0], column), y = key(b[0], column), result;
        if (numeric) {
          var fx = x === "" ? NaN : Number(x), fy = y === "" ? NaN : Number(y);
          if (isNaN(fx) || isNaN(fy)) {  // none last, whichever the direction
            result = isNaN(fx) === isNaN(fy) ? 0 : (isNaN(fx) ? 1 : -1);
            return result || a[1] - b[1];
          }
          result = fx - fy;
        } else {
          result = x.localeCompare(y, undefined, {numeric: true});
        }
        return (ascending ? result : -result) || a[1] - b[1];  // stable: the suite's order between equals
      });
      order.forEach(function (pair) { body.appendChild(pair[0]); });
    }
    th.addEventListener("click", sort);
    th.addEventListener("keydown", function (event) {
      if (event.key === "Enter" || event.key === " ") { event.preventDefault(); sort(); }
    });
  });
}());
