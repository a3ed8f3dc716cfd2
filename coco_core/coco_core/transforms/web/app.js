// CoCo transforms page: the frame tree, live over /ws/graph, and watched lookups, live over /ws/transforms.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const wsUrl = (path) => (location.protocol === "https:" ? "wss://" : "ws://") + location.host + path;
  const fmt = (values) => values.map((x) => (x === null ? "?" : x.toFixed(4))).join("  ");
  const edgeKey = (edge) => edge.parent + "\u0000" + edge.child;

  function el(tag, className, text) {
    const node = document.createElement(tag);
    if (className) node.className = className;
    if (text !== undefined) node.textContent = text;
    return node;
  }

  // ---- the graph ----------------------------------------------------------------------------------
  let structure = "";
  let valueElements = new Map();

  function edgeValue(edge) {
    if (edge.error) return "error: " + edge.error;
    if (edge.joint && edge.value !== undefined) return `${edge.joint} = ${edge.value === null ? "?" : edge.value.toFixed(4)}`;
    if (edge.joint) return edge.joint;
    if (edge.translation) return "t " + fmt(edge.translation);
    return "no sample yet";
  }

  function buildTree(graph) {
    const children = new Map(graph.frames.map((frame) => [frame, []]));
    const hasParent = new Set();
    for (const edge of graph.edges) {
      (children.get(edge.parent) || []).push(edge);
      hasParent.add(edge.child);
    }
    const seen = new Set();
    valueElements = new Map();

    function node(frame, edge) {
      seen.add(frame);
      const item = el("li");
      const name = el("span", "frame", frame);
      name.title = "watch this frame as the source";
      name.addEventListener("click", () => { $("source").value = frame; });
      item.append(name);
      if (edge) {
        const value = el("span", "value", edgeValue(edge));
        valueElements.set(edgeKey(edge), value);
        item.append(el("span", "kind " + edge.kind, edge.kind), value);
      }
      const list = el("ul");
      for (const next of children.get(frame) || []) {
        if (seen.has(next.child)) {
          list.append(el("li", "also", `→ ${next.child} (${next.kind}; also reached another way)`));
        } else {
          list.append(node(next.child, next));
        }
      }
      if (list.children.length) item.append(list);
      return item;
    }

    const tree = $("tree");
    tree.replaceChildren();
    // Roots first (frames that are no edge's child), then whatever a cycle left unvisited.
    for (const frame of graph.frames.filter((f) => !hasParent.has(f)).concat(graph.frames)) {
      if (!seen.has(frame)) tree.append(node(frame, null));
    }
  }

  function updateSelects(frames) {
    for (const id of ["target", "source"]) {
      const select = $(id);
      const chosen = select.value;
      select.replaceChildren(...frames.map((frame) => el("option", "", frame)));
      if (frames.includes(chosen)) select.value = chosen;
    }
  }

  function renderGraph(graph) {
    const key = JSON.stringify([graph.frames, graph.edges.map((e) => [e.parent, e.child, e.kind])]);
    if (key !== structure) {
      structure = key;
      buildTree(graph);
      updateSelects(graph.frames);
      if (lookups.some((l) => l.invalid)) {  // a missing frame may exist now
        for (const lookup of lookups) lookup.invalid = false;
        connectLookups();
      }
    }
    for (const edge of graph.edges) {
      const value = valueElements.get(edgeKey(edge));
      if (value) value.textContent = edgeValue(edge);
    }
    $("counts").textContent = `${graph.frames.length} frames, ${graph.edges.length} edges, version ${graph.version}`;
  }

  function connectGraph() {
    const socket = new WebSocket(wsUrl("/ws/graph?rate=10"));
    socket.onopen = () => { $("status").textContent = "live"; $("status").className = "status live"; };
    socket.onmessage = (event) => renderGraph(JSON.parse(event.data).graph);
    socket.onclose = () => {
      $("status").textContent = "disconnected, retrying…";
      $("status").className = "status";
      setTimeout(connectGraph, 1000);
    };
  }

  // ---- lookups ------------------------------------------------------------------------------------
  const lookups = [];  // {target, source, invalid, count, cells}
  let lookupSocket = null;

  function pairsQuery(list) {
    const query = new URLSearchParams();
    for (const lookup of list) {
      query.append("target", lookup.target);
      query.append("source", lookup.source);
    }
    return query.toString();
  }

  function showError(lookup, text) {
    lookup.cells.translation.textContent = text;
    lookup.cells.translation.className = "error";
    lookup.cells.quaternion.textContent = "";
  }

  function addLookup(target, source) {
    if (!target || !source || lookups.some((l) => l.target === target && l.source === source)) return;
    const row = el("tr");
    const cells = { translation: el("td", "num", "…"), quaternion: el("td", "num"), count: el("td", "num", "0") };
    const remove = el("button", "", "×");
    remove.title = "stop watching";
    const lookup = { target, source, invalid: false, count: 0, cells };
    remove.addEventListener("click", () => {
      lookups.splice(lookups.indexOf(lookup), 1);
      row.remove();
      history.replaceState(null, "", "?" + pairsQuery(lookups));
      connectLookups();
    });
    const removeCell = el("td");
    removeCell.append(remove);
    row.append(el("td", "", `${target} ← ${source}`), cells.translation, cells.quaternion, cells.count, removeCell);
    $("lookups").tBodies[0].append(row);
    lookups.push(lookup);
    history.replaceState(null, "", "?" + pairsQuery(lookups));
  }

  function update(entry) {
    const lookup = lookups.find((l) => l.target === entry.target && l.source === entry.source);
    if (!lookup) return;
    if (entry.error) {
      showError(lookup, entry.error);
      return;
    }
    lookup.count += 1;
    lookup.cells.translation.textContent = fmt(entry.translation);
    lookup.cells.translation.className = "num";
    lookup.cells.quaternion.textContent = fmt(entry.quaternion);
    lookup.cells.count.textContent = String(lookup.count);
  }

  // The server refuses a whole socket when one pair has an unknown frame: ask it why, leave that
  // pair out until the graph's structure changes, and connect again with the others.
  // Returns whether it found such a pair.
  async function explainRefusal(list) {
    let found = false;
    for (const lookup of list) {
      try {
        const answer = await fetch("api/lookup?" + pairsQuery([lookup]));
        if (answer.status === 404) {  // unknown frame or no path (409: no value yet, which streams fine)
          lookup.invalid = found = true;
          showError(lookup, (await answer.json()).error);
        }
      } catch (error) { /* the server is gone; the graph socket shows it */ }
    }
    return found;
  }

  function connectLookups() {
    if (lookupSocket) {
      lookupSocket.onclose = null;
      lookupSocket.close();
      lookupSocket = null;
    }
    const list = lookups.filter((l) => !l.invalid);
    if (!list.length) return;
    const socket = new WebSocket(wsUrl("/ws/transforms?" + pairsQuery(list)));
    let opened = false;
    socket.onopen = () => { opened = true; };
    socket.onmessage = (event) => { for (const entry of JSON.parse(event.data).transforms) update(entry); };
    socket.onclose = async () => {
      const refused = !opened && await explainRefusal(list);
      setTimeout(() => { if (lookupSocket === socket) connectLookups(); }, refused ? 0 : 1000);
    };
    lookupSocket = socket;
  }

  $("add-lookup").addEventListener("submit", (event) => {
    event.preventDefault();
    addLookup($("target").value, $("source").value);
    connectLookups();
  });

  const query = new URLSearchParams(location.search);
  const targets = query.getAll("target"), sources = query.getAll("source");
  targets.forEach((target, index) => addLookup(target, sources[index]));
  connectLookups();
  connectGraph();
})();
