-- logbook schema 1 (packs, blobs, sources, events) as written by hand for the tests (sqlite)
CREATE TABLE logbook_meta (key VARCHAR(64) PRIMARY KEY, value TEXT NOT NULL)
;
CREATE TABLE packs (id INTEGER PRIMARY KEY, name VARCHAR(200) NOT NULL UNIQUE, "label_capacity_Ah" FLOAT, chemistry VARCHAR(20), cells INTEGER, created_at VARCHAR(40) NOT NULL)
;
CREATE TABLE blobs (sha256 VARCHAR(64) PRIMARY KEY, compression VARCHAR(10) NOT NULL, size_bytes BIGINT NOT NULL, data BLOB NOT NULL)
;
CREATE TABLE sources (id INTEGER PRIMARY KEY, sha256 VARCHAR(64) NOT NULL UNIQUE, pack_id INTEGER NOT NULL REFERENCES packs(id), file_name VARCHAR(500) NOT NULL, path TEXT, size_bytes BIGINT NOT NULL, format VARCHAR(40) NOT NULL, added_at VARCHAR(40) NOT NULL, options_json TEXT NOT NULL, notes_json TEXT NOT NULL)
;
CREATE TABLE events (id INTEGER PRIMARY KEY, source_id INTEGER NOT NULL REFERENCES sources(id), idx INTEGER NOT NULL, pack_id INTEGER NOT NULL REFERENCES packs(id), kind VARCHAR(20) NOT NULL, start_time VARCHAR(40), duration_s FLOAT, "discharged_Ah" FLOAT, "discharged_Wh" FLOAT, "mean_current_A" FLOAT, "max_current_A" FLOAT, "rest_voltage_V" FLOAT, "rest_after_V" FLOAT, rest_after_s FLOAT, "min_voltage_V" FLOAT, "end_voltage_V" FLOAT, "end_current_A" FLOAT, resistance_ohm FLOAT, resistance_low_ohm FLOAT, resistance_high_ohm FLOAT, "temperature_start_C" FLOAT, "temperature_max_C" FLOAT, "ambient_C" FLOAT, reaches_knee BOOLEAN NOT NULL, cells INTEGER, samples INTEGER NOT NULL, curve_json TEXT NOT NULL, UNIQUE (source_id, idx))
;
INSERT INTO logbook_meta (key, value) VALUES ('schema_version', '1')
;
