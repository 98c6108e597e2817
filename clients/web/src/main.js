// main.js: the single-page app's router. Pages: #/scenes, #/scenes/NAME, #/viewer/NAME, #/upload,
// #/dashboard, #/token. A link of the form #token=SECRET (what `make demo` prints) stores the token
// for this browser tab and is removed from the address bar.
import "./style.css";
import * as api from "./api.js";
import * as dashboard from "./dashboard.js";
import * as scenes from "./scenes.js";
import * as upload from "./upload.js";
import { el, field } from "./ui.js";

const main = document.getElementById("main");
let cleanup = null; // the current page's teardown (event streams, timers, WebGL)

function navigate(hash) {
  if (location.hash === hash) route();
  else location.hash = hash;
}

function tokenPage() {
  const input = el("input", { id: "token", type: "password", autocomplete: "off", value: api.token() });
  const form = el("form", { class: "card" },
    el("h1", {}, "Access token"),
    el("p", {}, "Paste a token made by `instascene token create` (the server's first start writes an admin token to DATA/auth/admin.token). It is kept in this tab only."),
    field("Token", input),
    el("button", { type: "submit" }, "Use this token"));
  form.addEventListener("submit", (e) => {
    e.preventDefault();
    api.setToken(input.value);
    navigate("#/scenes");
  });
  main.replaceChildren(form);
  input.focus();
}

async function route() {
  if (location.hash.startsWith("#token=")) {
    api.setToken(decodeURIComponent(location.hash.slice("#token=".length)));
    history.replaceState(null, "", `${location.pathname}#/scenes`);
  }
  cleanup?.();
  cleanup = null;
  const [page, arg] = location.hash.replace(/^#\/?/, "").split("/");
  const name = arg ? decodeURIComponent(arg) : "";
  for (const a of document.querySelectorAll("nav a"))
    a.toggleAttribute("aria-current", a.getAttribute("href") === `#/${page}`);
  if (!api.token() && page !== "token") return tokenPage();
  switch (page) {
    case "upload":
      upload.render(main, navigate);
      break;
    case "dashboard":
      cleanup = dashboard.render(main);
      break;
    case "token":
      tokenPage();
      break;
    case "viewer": {
      const viewer = await import("./viewer.js"); // three.js and Spark load with the viewer only
      cleanup = viewer.render(main, name);
      break;
    }
    case "scenes":
      cleanup = name ? scenes.renderScene(main, name) : scenes.renderList(main);
      break;
    default:
      navigate("#/scenes");
  }
}

window.addEventListener("hashchange", route);
route();
