// Report writers: JSON for machines, Markdown for people.
#include "ltmapper/eval/report.hpp"
#include "ltmapper/io/json.hpp"
#include "ltmapper/io/io.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>
#include <utility>

namespace ltm::eval {
namespace {

// ------------------------------------------------------------------------------------ JSON
void WriteStats(io::json::Writer& w, const std::string& key, const ErrorStats& s) {
  w.BeginObject(key)
      .Int("n", (long long)s.n)
      .Number("rmse", s.rmse)
      .Number("mean", s.mean)
      .Number("median", s.median)
      .Number("max", s.max)
      .EndObject();
}

void WritePoseErrors(io::json::Writer& w, const std::string& key, const PoseErrors& e) {
  w.BeginObject(key);
  WriteStats(w, "trans_m", e.trans_m);
  WriteStats(w, "rot_deg", e.rot_deg);
  w.EndObject();
}

void WritePrf(io::json::Writer& w, const std::string& key, const PrfStats& s) {
  w.BeginObject(key)
      .Int("predicted", (long long)s.predicted)
      .Int("predicted_matched", (long long)s.predicted_matched)
      .Int("truth", (long long)s.truth)
      .Int("truth_matched", (long long)s.truth_matched)
      .Number("precision", s.precision)
      .Number("recall", s.recall)
      .Number("f1", s.f1)
      .EndObject();
}

void WriteTraj(io::json::Writer& w, const TrajResult& t) {
  w.BeginObject("traj").String("align", t.align).String("rpe_unit", t.rpe_unit).Number("rpe_delta", t.rpe_delta);
  WritePoseErrors(w, "ate", t.ate);
  WritePoseErrors(w, "rpe", t.rpe);
  WritePoseErrors(w, "consistency", t.consistency);
  w.BeginArray("sessions");
  for (const auto& s : t.sessions) {
    w.BeginObject().String("name", s.name).Int("poses", (long long)s.poses);
    WritePoseErrors(w, "ate", s.ate);
    WritePoseErrors(w, "rpe", s.rpe);
    w.BeginArray("T_truth_est");  // row-major 3x4
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) w.Number(s.T_truth_est.matrix()(r, c));
    w.EndArray().EndObject();
  }
  w.EndArray();
  w.BeginArray("consistency_sessions");
  for (const auto& c : t.consistency_sessions) {
    w.BeginObject().String("name", c.name).Int("pairs", (long long)c.pairs).Int("skipped", (long long)c.skipped);
    WritePoseErrors(w, "error", c.error);
    w.EndObject();
  }
  w.EndArray();
  w.BeginArray("missing");
  for (const auto& m : t.missing) w.String({}, m);
  w.EndArray().EndObject();
}

void WriteHd(io::json::Writer& w, const HdResult& h) {
  w.BeginObject("hd")
      .Number("match_dist_m", h.match_dist_m)
      .Int("output_points", (long long)h.output_points)
      .Int("static_total", (long long)h.static_total)
      .Int("static_preserved", (long long)h.static_preserved)
      .Int("dynamic_total", (long long)h.dynamic_total)
      .Int("dynamic_removed", (long long)h.dynamic_removed)
      .Int("ignored", (long long)h.ignored)
      .Number("sa", h.sa)
      .Number("da", h.da)
      .Number("aa", h.aa);
  if (h.separable_given)
    w.Int("separable_total", (long long)h.separable_total)
        .Int("separable_removed", (long long)h.separable_removed)
        .Number("da_separable", h.da_separable);
  w.BeginArray("classes");
  for (const auto& c : h.classes)
    w.BeginObject()
        .String("name", c.name)
        .Int("total", (long long)c.total)
        .Int("preserved", (long long)c.preserved)
        .Int("removed", (long long)(c.total - c.preserved))
        .EndObject();
  w.EndArray().EndObject();
}

void WriteLd(io::json::Writer& w, const LdResult& l) {
  w.BeginObject("ld").Number("match_dist_m", l.match_dist_m);
  WritePrf(w, "pd_strong", l.pd_strong);
  WritePrf(w, "pd_weak", l.pd_weak);
  WritePrf(w, "pd", l.pd);
  WritePrf(w, "nd_strong", l.nd_strong);
  WritePrf(w, "nd_weak", l.nd_weak);
  WritePrf(w, "nd", l.nd);
  if (l.objects_given) {
    WritePrf(w, "pd_objects", l.pd_objects);
    WritePrf(w, "nd_objects", l.nd_objects);
  }
  if (l.separable_given) {
    WritePrf(w, "pd_separable", l.pd_separable);
    WritePrf(w, "nd_separable", l.nd_separable);
  }
  w.BeginArray("bands");
  for (const LdBand& b : l.bands) {
    w.BeginObject().Number("min_m", b.min_m).Number("max_m", b.max_m);  // last max_m +inf: written as null
    WritePrf(w, "pd", b.pd);
    WritePrf(w, "nd", b.nd);
    w.EndObject();
  }
  w.EndArray();
  w.BeginObject("weak_nd_kept")
      .Bool("kept_map_given", l.kept_map_given)
      .Int("truth", (long long)l.weak_nd_truth)
      .Int("kept", (long long)l.weak_nd_kept)
      .Number("fraction", l.weak_nd_preserved)
      .EndObject();
  w.BeginObject("pd_strength")
      .Int("matched", (long long)l.pd_matched)
      .Int("correct", (long long)l.pd_strength_correct)
      .Number("accuracy", l.pd_strength_accuracy)
      .EndObject();
  w.BeginObject("nd_strength")
      .Int("matched", (long long)l.nd_matched)
      .Int("correct", (long long)l.nd_strength_correct)
      .Number("accuracy", l.nd_strength_accuracy)
      .EndObject();
  w.EndObject();
}

void WriteRestore(io::json::Writer& w, const RestoreResult& r) {
  w.BeginObject("restore")
      .Number("patch_m", r.patch_m)
      .Int("min_points", r.min_points)
      .String("chamfer", r.chamfer)
      .Int("points_a", (long long)r.points_a)
      .Int("points_b", (long long)r.points_b)
      .Int("patches_a", (long long)r.patches_a)
      .Int("patches_b", (long long)r.patches_b)
      .Int("patches_both", (long long)r.patches_both)
      .Int("np_valid", (long long)r.np_valid)
      .Number("max", r.max)
      .Number("mean", r.mean)
      .Number("variance", r.variance)
      .Number("same_class_m", r.same_class_m)
      .Number("same_class_a", r.same_class_a)
      .Number("same_class_b", r.same_class_b);
  w.BeginArray("np_above");
  for (std::size_t k = 0; k < r.thresholds.size(); ++k)
    w.BeginObject().Number("threshold", r.thresholds[k]).Int("patches", (long long)r.np_above[k]).EndObject();
  w.EndArray().EndObject();
}

void WriteStorage(io::json::Writer& w, const StorageResult& s) {
  w.BeginObject("storage").BeginArray("items");
  for (const auto& it : s.items)
    w.BeginObject()
        .String("path", it.path)
        .Int("bytes", (long long)it.bytes)
        .Int("files", (long long)it.files)
        .Number("ratio_to_first", it.ratio_to_first)
        .EndObject();
  w.EndArray().BeginArray("costs");
  for (const auto& c : s.costs)
    w.BeginObject().String("label", c.label).Number("wall_s", c.wall_s).Number("peak_bytes", c.peak_bytes).EndObject();
  w.EndArray().EndObject();
}

void WritePrf(io::json::Writer& w, const ObjectsPrf& p, const char* key = nullptr) {
  (key ? w.BeginObject(key) : w.BeginObject())
      .String("name", p.name)
      .Int("truth_objects", (long long)p.truth_objects)
      .Int("found", (long long)p.found)
      .Int("clusters", (long long)p.clusters)
      .Int("true_clusters", (long long)p.true_clusters)
      .Number("precision", p.precision)
      .Number("recall", p.recall)
      .Number("f1", p.f1)
      .EndObject();
}

void WriteMoved(io::json::Writer& w, const MovedPrf& m) {
  w.BeginObject()
      .String("name", m.name)
      .Int("truth_moves", (long long)m.truth_moves)
      .Int("found", (long long)m.found)
      .Int("linked", (long long)m.linked)
      .Int("reported", (long long)m.reported)
      .Int("true_reported", (long long)m.true_reported)
      .Number("precision", m.precision)
      .Number("recall", m.recall)
      .EndObject();
}

void WriteClusterScores(io::json::Writer& w, const ObjectsResult& r) {
  w.BeginArray("clusters_scored");
  for (const auto& c : r.cluster_scores)
    w.BeginObject()
        .String("pair", c.pair)
        .Int("id", c.id)
        .String("change", c.change)
        .Int("points", (long long)c.points)
        .Int("best_truth", c.best_truth)
        .Number("best_iou", c.best_iou)
        .Bool("true_object", c.true_object)
        .Bool("moved", c.moved)
        .Int("partner", c.partner)
        .Int("track", c.track)
        .EndObject();
  w.EndArray();
}

void WriteObjectsResult(io::json::Writer& w, const ObjectsResult& r) {
  w.BeginObject("objects")
      .Number("match_dist_m", r.match_dist_m)
      .Number("voxel_m", r.voxel_m)
      .Number("min_iou", r.min_iou)
      .Int("clusters", (long long)r.clusters)
      .Int("truth_objects", (long long)r.truth_objects)
      .Int("found", (long long)r.found)
      .Number("found_fraction", r.found_fraction)
      .Number("precision", r.all.precision)
      .Number("recall", r.all.recall)
      .Number("f1", r.all.f1);
  WritePrf(w, r.all, "all");
  WritePrf(w, r.observable, "observable");
  w.BeginArray("per_pair");
  for (const auto& p : r.per_pair) WritePrf(w, p);
  w.EndArray().BeginArray("observable_per_pair");
  for (const auto& p : r.observable_per_pair) WritePrf(w, p);
  w.EndArray().BeginArray("per_change");
  for (const auto& p : r.per_change) WritePrf(w, p);
  w.EndArray().BeginArray("per_class");
  for (const auto& p : r.per_class) WritePrf(w, p);
  w.EndArray().BeginArray("moved");
  for (const auto& m : r.moved) WriteMoved(w, m);
  w.EndArray()
      .BeginObject("identity")
      .Int("same", (long long)r.identity.same)
      .Int("same_tracked", (long long)r.identity.same_tracked)
      .Int("tracked", (long long)r.identity.tracked)
      .Int("tracked_wrong", (long long)r.identity.tracked_wrong)
      .EndObject();
  WriteClusterScores(w, r);
  w.BeginArray("objects");
  for (const auto& o : r.objects)
    w.BeginObject()
        .String("pair", o.pair)
        .Int("id", o.id)
        .String("class", o.cls)
        .String("placement", o.placement)
        .Int("session", o.session)
        .Int("points", (long long)o.points)
        .Int("best_cluster", o.best_cluster)
        .Int("cluster_points", (long long)o.cluster_points)
        .Number("best_iou", o.best_iou)
        .Int("change_points", o.change_points)
        .Number("observed_share", o.observed_share)
        .Bool("scored", o.scored)
        .Bool("found", o.found)
        .EndObject();
  w.EndArray().EndObject();
}

void WriteLiveMeta(io::json::Writer& w, const LiveMetaResult& r) {
  w.BeginObject("livemeta")
      .Number("match_dist_m", r.match_dist_m)
      .Number("min_fraction", r.min_fraction)
      .Int("live_points", (long long)r.live_points)
      .Int("meta_points", (long long)r.meta_points)
      .Int("added", (long long)r.added)
      .Int("added_in_live", (long long)r.added_in_live)
      .Int("added_in_meta", (long long)r.added_in_meta)
      .Int("removed", (long long)r.removed)
      .Int("removed_in_live", (long long)r.removed_in_live)
      .Int("removed_in_meta", (long long)r.removed_in_meta)
      .BeginArray("objects");
  for (const auto& o : r.objects)
    w.BeginObject()
        .Int("id", o.id)
        .String("class", o.cls)
        .String("placement", o.placement)
        .String("change", o.added ? "added" : "removed")
        .Int("points", (long long)o.points)
        .Number("live_fraction", o.live_fraction)
        .Number("meta_fraction", o.meta_fraction)
        .Bool("scored", o.scored)
        .Bool("in_live", o.in_live)
        .Bool("in_meta", o.in_meta)
        .EndObject();
  w.EndArray().EndObject();
}

// -------------------------------------------------------------------------------- Markdown
std::string Fmt(double v, int digits = 3) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.*f", digits, v);
  return buf;
}

std::string Bytes(double b) {
  if (!std::isfinite(b)) return "n/a";
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int u = 0;
  while (b >= 1024.0 && u < 4) {
    b /= 1024.0;
    ++u;
  }
  char buf[64];
  std::snprintf(buf, sizeof(buf), u == 0 ? "%.0f %s" : "%.2f %s", b, units[u]);
  return buf;
}

std::string Row(const std::vector<std::string>& cells) {
  std::string s = "|";
  for (const auto& c : cells) s += " " + c + " |";
  return s + "\n";
}

std::string Header(const std::vector<std::string>& cells) {
  std::string s = Row(cells) + "|";
  for (std::size_t i = 0; i < cells.size(); ++i) s += i == 0 ? "---|" : "---:|";
  return s + "\n";
}

std::vector<std::string> ErrCells(const std::string& label, const PoseErrors& e) {
  return {label, std::to_string(e.trans_m.n), Fmt(e.trans_m.rmse), Fmt(e.trans_m.mean), Fmt(e.trans_m.max),
          Fmt(e.rot_deg.rmse), Fmt(e.rot_deg.mean), Fmt(e.rot_deg.max)};
}
const std::vector<std::string> kErrHeader = {"", "n", "trans RMSE [m]", "trans mean [m]", "trans max [m]",
                                             "rot RMSE [deg]", "rot mean [deg]", "rot max [deg]"};

void MdTraj(std::ostringstream& md, const TrajResult& t) {
  md << "## Trajectories\n\nAlignment: " << t.align << "; RPE over " << Fmt(t.rpe_delta, 2) << " "
     << t.rpe_unit << ".\n\n";
  md << Header(kErrHeader) << Row(ErrCells("ATE (all)", t.ate)) << Row(ErrCells("RPE (all)", t.rpe));
  for (const auto& s : t.sessions) {
    md << Row(ErrCells("ATE " + s.name, s.ate)) << Row(ErrCells("RPE " + s.name, s.rpe));
  }
  if (!t.consistency_sessions.empty()) {
    md << "\nInter-session consistency (query keyframe vs nearest central keyframe, relative pose "
          "error):\n\n"
       << Header(kErrHeader) << Row(ErrCells("all queries", t.consistency));
    for (const auto& c : t.consistency_sessions)
      md << Row(ErrCells(c.name + " (" + std::to_string(c.skipped) + " far kf skipped)", c.error));
  }
  if (!t.missing.empty()) {
    md << "\nSessions without an estimate (not scored):";
    for (const auto& m : t.missing) md << " " << m;
    md << "\n";
  }
  md << "\n";
}

void MdHd(std::ostringstream& md, const HdResult& h) {
  md << "## HD removal\n\nKTH DynamicMap rule, match distance " << Fmt(h.match_dist_m, 3) << " m, "
     << h.output_points << " output points.\n\n"
     << Header({"SA", "DA", "AA", "static kept / total", "HD removed / total", "ignored"})
     << Row({Fmt(h.sa, 4), Fmt(h.da, 4), Fmt(h.aa, 4),
             std::to_string(h.static_preserved) + " / " + std::to_string(h.static_total),
             std::to_string(h.dynamic_removed) + " / " + std::to_string(h.dynamic_total),
             std::to_string(h.ignored)})
     << "\n";
  if (h.separable_given)
    md << "DA over the HD points farther than the static-reference distance from every static truth point "
          "(the 'hd near static' row cannot be told apart at the match distance): "
       << Fmt(h.da_separable, 4) << " (" << h.separable_removed << " / " << h.separable_total << ").\n\n";
  md << Header({"class", "points", "preserved", "removed", "preserved %"});
  for (const auto& c : h.classes)
    md << Row({c.name, std::to_string(c.total), std::to_string(c.preserved), std::to_string(c.total - c.preserved),
               Fmt(c.total ? 100.0 * double(c.preserved) / double(c.total) : kNaN, 2)});
  md << "\n";
}

void MdLd(std::ostringstream& md, const LdResult& l) {
  md << "## LD changes\n\nMatch distance " << Fmt(l.match_dist_m, 3) << " m.\n\n"
     << Header({"class", "predicted", "truth", "precision", "recall", "F1"});
  const std::pair<const char*, const PrfStats*> rows[] = {{"PD strong", &l.pd_strong}, {"PD weak", &l.pd_weak},
                                                          {"PD (all)", &l.pd},          {"ND strong", &l.nd_strong},
                                                          {"ND weak", &l.nd_weak},      {"ND (all)", &l.nd}};
  for (const auto& [name, s] : rows)
    md << Row({name, std::to_string(s->predicted), std::to_string(s->truth), Fmt(s->precision, 4),
               Fmt(s->recall, 4), Fmt(s->f1, 4)});
  md << "\n- Weak ND kept in the map: "
     << (l.kept_map_given ? std::to_string(l.weak_nd_kept) + " / " + std::to_string(l.weak_nd_truth) + " = " +
                                Fmt(l.weak_nd_preserved, 4)
                          : std::string("n/a (no kept map)"))
     << "\n- PD strength correct: " << l.pd_strength_correct << " / " << l.pd_matched << " = "
     << Fmt(l.pd_strength_accuracy, 4) << "\n- ND strength correct: " << l.nd_strength_correct << " / "
     << l.nd_matched << " = " << Fmt(l.nd_strength_accuracy, 4) << "\n";
  if (l.objects_given)
    md << "- Recall over the changed objects' points alone (the rest of the truth is coverage: surfaces both "
          "sessions have that one never observed): PD "
       << l.pd_objects.truth_matched << " / " << l.pd_objects.truth << " = " << Fmt(l.pd_objects.recall, 4) << ", ND "
       << l.nd_objects.truth_matched << " / " << l.nd_objects.truth << " = " << Fmt(l.nd_objects.recall, 4) << "\n";
  if (l.separable_given)
    md << "- Recall over the separable truth points (farther than the match distance from every surface the "
          "other session sampled; nearer, a change cannot be told from that surface): PD "
       << l.pd_separable.truth_matched << " / " << l.pd_separable.truth << " = " << Fmt(l.pd_separable.recall, 4)
       << ", ND " << l.nd_separable.truth_matched << " / " << l.nd_separable.truth << " = "
       << Fmt(l.nd_separable.recall, 4) << "\n";
  md << "\n";
  if (l.bands.empty()) return;
  md << "By distance from the session that had to observe the place (PD: nearest central keyframe, ND: "
        "nearest query keyframe):\n\n"
     << Header({"distance [m]", "PD truth", "PD precision", "PD recall", "ND truth", "ND precision", "ND recall"});
  for (const LdBand& b : l.bands) {
    const std::string band = std::isinf(b.max_m) ? ">= " + Fmt(b.min_m, 0) : Fmt(b.min_m, 0) + " - " + Fmt(b.max_m, 0);
    md << Row({band, std::to_string(b.pd.truth), Fmt(b.pd.precision, 4), Fmt(b.pd.recall, 4),
               std::to_string(b.nd.truth), Fmt(b.nd.precision, 4), Fmt(b.nd.recall, 4)});
  }
  md << "\n";
}

void MdRestore(std::ostringstream& md, const RestoreResult& r) {
  const std::string unit = r.chamfer == "fan_squared" ? "m^2" : "m";
  md << "## Restoration (Chamfer distance per " << Fmt(r.patch_m, 2) << " m patch, >= " << r.min_points
     << " points in both maps, CD = " << (r.chamfer == "fan_squared" ? "sum of mean squared NN distances"
                                                                     : "mean of the two mean NN distances")
     << ")\n\n";
  std::vector<std::string> head = {"max [" + unit + "]", "mean [" + unit + "]", "var"};
  std::vector<std::string> cells = {Fmt(r.max), Fmt(r.mean), Fmt(r.variance)};
  for (std::size_t k = 0; k < r.thresholds.size(); ++k) {
    head.push_back("NP CD>" + Fmt(r.thresholds[k], 1));
    cells.push_back(std::to_string(r.np_above[k]));
  }
  head.push_back("NP valid");
  cells.push_back(std::to_string(r.np_valid));
  md << Header(head) << Row(cells) << "\nPoints A/B: " << r.points_a << " / " << r.points_b
     << "; occupied patches A/B/both: " << r.patches_a << " / " << r.patches_b << " / " << r.patches_both
     << ".\n\n";
  if (!std::isnan(r.same_class_a))
    md << "Same class within " << Fmt(r.same_class_m, 2) << " m: " << Fmt(100.0 * r.same_class_a, 2)
       << " % of A's points, " << Fmt(100.0 * r.same_class_b, 2) << " % of B's.\n\n";
}

void MdStorage(std::ostringstream& md, const StorageResult& s) {
  md << "## Storage and cost\n\n";
  if (!s.items.empty()) {
    md << Header({"path", "bytes", "size", "files", "ratio to first"});
    for (const auto& it : s.items)
      md << Row({"`" + it.path + "`", std::to_string(it.bytes), Bytes(double(it.bytes)), std::to_string(it.files),
                 Fmt(it.ratio_to_first, 3)});
    md << "\n";
  }
  if (!s.costs.empty()) {
    md << Header({"stage", "wall time [s]", "peak memory"});
    for (const auto& c : s.costs) md << Row({c.label, Fmt(c.wall_s, 2), Bytes(c.peak_bytes)});
    md << "\n";
  }
}

// An object id, or "-" for none (-1).
std::string IdOrDash(int id) { return id < 0 ? std::string("-") : std::to_string(id); }

// What a user reads, judged: every reported object (objects.csv) with the truth object of its pair
// that overlaps it most, and whether that makes it a true object.
void MdObjectVerdicts(std::ostringstream& md, const ObjectsResult& r) {
  md << "\nReported objects (objects.csv), each with the truth object of its pair that overlaps it most:\n\n"
     << Header({"pair", "id", "change", "partner", "track", "points", "best truth", "IoU", "true object"});
  std::map<std::pair<std::string, int>, std::string> cls;  // (pair, truth id) -> its class
  for (const auto& o : r.objects) cls[{o.pair, o.id}] = o.cls;
  for (const auto& c : r.cluster_scores) {
    const auto t = cls.find({c.pair, c.best_truth});
    const std::string truth = IdOrDash(c.best_truth) + (t == cls.end() ? "" : " (" + t->second + ")");
    md << Row({c.pair, std::to_string(c.id), c.moved ? std::string("moved") : c.change, IdOrDash(c.partner),
               IdOrDash(c.track), std::to_string(c.points), truth, Fmt(c.best_iou, 3),
               c.true_object ? std::string("yes") : std::string("no")});
  }
}

void MdObjects(std::ostringstream& md, const ObjectsResult& r) {
  md << "## Changed objects\n\nTruth: LD objects present in exactly one session of the pair; point IoU "
        "after a " << Fmt(r.voxel_m, 2) << " m voxel filter, match distance " << Fmt(r.match_dist_m, 2)
     << " m; found when IoU >= " << Fmt(r.min_iou, 2)
     << "; not scored: too few scanned points or too few detectable change points (truth PD, strong ND).\n\n"
     << Header({"truth objects", "found", "found fraction", "clusters"})
     << Row({std::to_string(r.truth_objects), std::to_string(r.found), Fmt(r.found_fraction, 3),
             std::to_string(r.clusters)})
     << "\nA cluster is a true object when a truth object of its pair reaches IoU >= " << Fmt(r.min_iou, 2)
     << ", else a false object. Precision = true clusters / clusters, recall = found / truth objects; "
        "change: appeared (PD clusters, objects of the pair's second session), disappeared (ND); class: the truth "
        "objects of the class, and the clusters that overlap one of them most; observable: the truth objects "
        "most of whose change points (changes.ply) the other session observed changed (weak PD, strong ND), "
        "against all clusters (the rest lies mostly in space one session never observed: coverage), "
        "per pair and over all pairs.\n\n"
     << Header({"slice", "truth objects", "found", "clusters", "true clusters", "precision", "recall", "F1"});
  std::vector<ObjectsPrf> rows;
  for (std::size_t i = 0; i < r.per_pair.size(); ++i) {
    rows.push_back(r.per_pair[i]);
    if (i < r.observable_per_pair.size()) rows.push_back(r.observable_per_pair[i]);
  }
  rows.insert(rows.end(), r.per_change.begin(), r.per_change.end());
  rows.insert(rows.end(), r.per_class.begin(), r.per_class.end());
  rows.push_back(r.all);
  rows.push_back(r.observable);
  for (const auto& p : rows)
    md << Row({p.name, std::to_string(p.truth_objects), std::to_string(p.found), std::to_string(p.clusters),
               std::to_string(p.true_clusters), Fmt(p.precision, 3), Fmt(p.recall, 3), Fmt(p.f1, 3)});
  md << "\nMoved objects (truth/objects.csv's partner: the same object gone from one place and new at another "
        "in the pair): a move is found when clusters reported as moved find both its ends, linked when those two "
        "name each other (or a row of each other's track) as partners; a cluster reported as moved is true when it finds an end of a move.\n\n"
     << Header({"slice", "truth moves", "found as moved", "linked", "clusters moved", "true", "precision", "recall"});
  for (const auto& m : r.moved)
    md << Row({m.name, std::to_string(m.truth_moves), std::to_string(m.found), std::to_string(m.linked),
               std::to_string(m.reported), std::to_string(m.true_reported), Fmt(m.precision, 3), Fmt(m.recall, 3)});
  const IdentityScore& id = r.identity;
  md << "\nIdentity across steps (objects.csv's track), over pairs of true clusters of different steps: "
     << id.same_tracked << " of the " << id.same << " that find one truth object share a track; " << id.tracked_wrong
     << " of the " << id.tracked << " that share a track find two objects that are not one move's ends.\n";
  MdObjectVerdicts(md, r);
  md << "\nTruth objects, each with the cluster that overlaps it most:\n\n"
     << Header({"pair", "id", "class", "placement", "in session", "points", "change points", "observed share",
                "best cluster", "cluster points", "IoU", "found"});
  for (const auto& o : r.objects)
    md << Row({o.pair, std::to_string(o.id), o.cls, o.placement, std::to_string(o.session), std::to_string(o.points),
               o.change_points < 0 ? std::string("n/a") : std::to_string(o.change_points),
               std::isnan(o.observed_share) ? std::string("n/a") : Fmt(o.observed_share, 2),
               IdOrDash(o.best_cluster),
               std::to_string(o.cluster_points), Fmt(o.best_iou, 3),
               !o.scored ? std::string("not scored") : o.found ? std::string("yes") : std::string("no")});
  md << "\n";
}

void MdLiveMeta(std::ostringstream& md, const LiveMetaResult& r) {
  auto frac = [](std::size_t a, std::size_t b) { return std::to_string(a) + " / " + std::to_string(b); };
  md << "## Live and meta map: new and removed objects since session 0\n\nAn object is in a map when >= "
     << Fmt(r.min_fraction, 2) << " of its truth points have a map point within " << Fmt(r.match_dist_m, 3)
     << " m (best view over the sessions where the object exists). Wanted: new objects in the live map "
        "and not in the meta map; removed objects in neither. Exceptions by design: a removed object "
        "placed `occluded` was never seen through (weak ND, kept in both maps); a new object placed "
        "`revealed` is strong PD (in the meta map too). "
     << "Live / meta map points: " << r.live_points << " / " << r.meta_points << ".\n\n"
     << Header({"objects", "total", "in live", "in meta"})
     << Row({"new since session 0", std::to_string(r.added), frac(r.added_in_live, r.added),
             frac(r.added_in_meta, r.added)})
     << Row({"removed since session 0", std::to_string(r.removed), frac(r.removed_in_live, r.removed),
             frac(r.removed_in_meta, r.removed)})
     << "\n"
     << Header({"id", "class", "placement", "change", "points", "live fraction", "meta fraction", "in live", "in meta"});
  auto yn = [](bool scored, bool v) { return !scored ? std::string("not scored") : v ? std::string("yes") : std::string("no"); };
  for (const auto& o : r.objects)
    md << Row({std::to_string(o.id), o.cls, o.placement, o.added ? "new" : "removed", std::to_string(o.points),
               Fmt(o.live_fraction, 3), Fmt(o.meta_fraction, 3), yn(o.scored, o.in_live), yn(o.scored, o.in_meta)});
  md << "\n";
}

}  // namespace

std::string ToJson(const Report& report) {
  io::json::Writer w;
  w.BeginObject();
  w.BeginObject("inputs");
  for (const auto& [k, v] : report.inputs) w.String(k, v);
  w.EndObject();
  if (report.traj) WriteTraj(w, *report.traj);
  if (report.hd) WriteHd(w, *report.hd);
  if (report.ld) WriteLd(w, *report.ld);
  if (report.restore) WriteRestore(w, *report.restore);
  if (report.storage) WriteStorage(w, *report.storage);
  if (report.objects) WriteObjectsResult(w, *report.objects);
  if (report.livemeta) WriteLiveMeta(w, *report.livemeta);
  w.EndObject();
  return w.str();
}

std::string ToMarkdown(const Report& report) {
  std::ostringstream md;
  md << "# ltmapper eval\n\n";
  if (!report.inputs.empty()) {
    for (const auto& [k, v] : report.inputs) md << "- " << k << ": `" << v << "`\n";
    md << "\n";
  }
  if (report.traj) MdTraj(md, *report.traj);
  if (report.hd) MdHd(md, *report.hd);
  if (report.ld) MdLd(md, *report.ld);
  if (report.restore) MdRestore(md, *report.restore);
  if (report.storage) MdStorage(md, *report.storage);
  if (report.objects) MdObjects(md, *report.objects);
  if (report.livemeta) MdLiveMeta(md, *report.livemeta);
  return md.str();
}

void WriteReport(const Report& report, const std::string& json_path, const std::string& md_path) {
  if (!json_path.empty()) {
    const std::string text = ToJson(report);
    io::WriteFileAtomic(json_path, [&](std::ostream& os) { os << text; });
  }
  if (!md_path.empty()) {
    const std::string text = ToMarkdown(report);
    io::WriteFileAtomic(md_path, [&](std::ostream& os) { os << text; });
  }
}

std::optional<double> JsonNumber(const std::string& json_text, const std::string& dotted_path) {
  const io::json::Value doc = io::json::Parse(json_text, "json");
  const io::json::Value* v = &doc;
  std::size_t start = 0;
  while (v && start <= dotted_path.size()) {
    const std::size_t dot = dotted_path.find('.', start);
    const std::string seg = dotted_path.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    if (v->type == io::json::Value::Type::kArray) {
      char* end = nullptr;
      const unsigned long idx = std::strtoul(seg.c_str(), &end, 10);
      v = (!seg.empty() && *end == '\0' && idx < v->arr.size()) ? &v->arr[idx] : nullptr;
    } else {
      v = v->Find(seg);
    }
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  if (!v || v->type != io::json::Value::Type::kNumber) return std::nullopt;
  return v->num;
}

}  // namespace ltm::eval
